"""``sray eval``: score any method's pretrained model on unseen scenes with the paper's generalization protocol
(docs/fleet.md, "``sray eval``"): every ``test`` view from its ``n_source`` fixed sources, every ``stride``-th pixel.
Writes ``metrics.json`` (model record, protocol, per-scene blocks, their unweighted mean, per-view scores) and every
view's PNGs in a new tracked run (metrics at the checkpoint's step, 0 without one). ``--calibrate`` first fits the
fast render's coarse confidence on validation rooms (:func:`calibrate`, docs/fleet.md, "Shifted splits")."""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from sray.data_tools.atomic import atomic_write_bytes, atomic_write_json
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.png import encode_png
from sray.data_tools.shards.manifest import read_manifest
from sray.model.calibration import fit_temperature, nll
from sray.model.fast_render import FastRender
from sray.model.metrics import DATASET_PROTOCOL, LPIPS_NOTE, PER_IMAGE_PROTOCOL, psnr
from sray.model.runtime import Runtime
from sray.model.ssim import SSIM_PROTOCOL, SSIM_WINDOW
from sray.model.view_render import render_view, strided_pixels
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.eval.eval_model import EvalModel, checkpoint_model
from sray.platform.eval.label_transfer import UNSEEN
from sray.platform.eval.view_scoring import ViewPrediction, class_ious, per_image_scores, score_scene
from sray.platform.tracking.registry import DEFAULT_TRACKER, get_tracker
from sray.platform.viz.palette import colorize
from sray.platform.viz.renders import error_map, render_panel

METRICS_FILE = "metrics.json"
CALIBRATION_FILE = "calibration.json"
"""File of an evaluation's output folder holding the calibration it used."""
SCORE_PATHS = {"miou": ("dataset_level", "miou"), "total_acc": ("dataset_level", "total_acc"),
               "class_avg_acc": ("dataset_level", "class_avg_acc"), "miou_per_image": ("per_image", "miou"),
               "psnr": ("colour", "psnr_db"), "ssim": ("colour", "ssim")}
"""Score name (``score_views``) -> (block, key) in a metrics.json scene block."""


def _finite_or_none(value: Any) -> Any:
    """JSON has no NaN: NaN/inf become null, recursively."""
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite_or_none(v) for v in value]
    return None if isinstance(value, float) and not math.isfinite(value) else value


def write_json_atomic(obj: Any, path: Path) -> Path:
    """Write ``obj`` as indented JSON (NaN as null) through a temporary name; returns ``path``."""
    atomic_write_json(Path(path), _finite_or_none(obj))
    return Path(path)


def training_scenes(shards: Path, count: int) -> list[str]:
    """The first ``count`` (at least 1) train scenes of ``shards`` by name: their held-out views measure fitting."""
    if count < 1:
        raise ValueError(f"{Path(shards) / 'manifest.json'}: {count} held-out training scenes asked for; ask for 1 "
                         "or more")
    manifest = read_manifest(Path(shards))
    return sorted(s for s, e in manifest.scenes.items() if e.meta.get("role", "train") == "train")[:count]


def select_scenes(shards: Path, scenes: list[str] | None) -> tuple[list[str], dict[str, dict]]:
    """The scenes to evaluate (default: every ``role == "test"`` scene) and their metadata; ValueError naming the
    manifest and the fix for unknown scenes or scenes without ``test`` views."""
    manifest = read_manifest(Path(shards))
    where = Path(shards) / "manifest.json"
    if scenes is None:
        scenes = sorted(s for s, e in manifest.scenes.items() if e.meta.get("role") == "test")
        if not scenes:
            raise ValueError(f"{where}: no scene has role 'test'; pass --scenes NAME ... explicitly")
    unknown = [s for s in scenes if s not in manifest.scenes]
    if unknown:
        raise ValueError(f"{where}: scenes {unknown} not found; known: {sorted(manifest.scenes)[:10]}")
    metas = {s: manifest.scenes[s].meta for s in scenes}
    empty = [s for s in scenes if not metas[s].get("splits", {}).get("test")]
    if empty:
        raise ValueError(f"{where}: scenes {empty} have no 'test' views to evaluate; pick scenes with a "
                         "'test' split (unseen test scenes have one)")
    return list(scenes), metas


def save_view_pngs(view: ViewPrediction, scene: str, class_names: list[str], ignore_id: int,
                   out_dir: Path) -> dict[str, str]:
    """Write one view's predicted and true semantics, error map and panel; {kind: path relative to ``out_dir``}."""
    gt, raw = view.gt_label.numpy(), view.pred_label.numpy()
    pred = np.where(raw == UNSEEN, ignore_id, raw)  # no prediction: blank
    stem = out_dir / "renders" / scene / str(view.query_id)
    images = {"pred": colorize(pred, len(class_names), ignore_id), "gt": colorize(gt, len(class_names), ignore_id),
              "error": error_map(raw, gt, ignore_id)}
    files = {kind: stem.with_name(f"{stem.name}_{kind}.png") for kind in images}
    for kind, image in images.items():
        atomic_write_bytes(files[kind], encode_png(image))
    files["panel"] = render_panel(pred, gt, view.pred_rgb.numpy(), view.gt_rgb.numpy(), class_names,
                                  stem.with_name(f"{stem.name}_panel.png"), ignore_id,
                                  title=f"zero-shot: {scene} view {view.query_id}")
    return {k: str(p.relative_to(out_dir)) for k, p in files.items()}


def scene_blocks(scores: dict[str, float | None], n_views: int) -> dict[str, Any]:
    """Scores of one scene (or their mean) in protocol-named blocks; ``ssim`` None when not scored."""
    return {
        "n_views": n_views,
        "dataset_level": {"protocol": DATASET_PROTOCOL, "miou": scores["miou"], "total_acc": scores["total_acc"],
                          "class_avg_acc": scores["class_avg_acc"]},
        "per_image": {"protocol": PER_IMAGE_PROTOCOL, "miou": scores["miou_per_image"]},
        "colour": {"psnr_db": scores["psnr"], "ssim": scores.get("ssim"), "ssim_protocol": SSIM_PROTOCOL,
                   "ssim_window": SSIM_WINDOW},
    }


def flat_metrics(report: dict[str, Any]) -> dict[str, float]:
    """Tracked metric keys ``<scene or mean>/<metric>`` of a metrics.json report (finite values only)."""
    out = {}
    for name, block in [*report["scenes"].items(), ("mean", report["mean"])]:
        values = {k: block[where][key] for k, (where, key) in SCORE_PATHS.items()}
        out |= {f"{name}/{k}": float(v) for k, v in values.items() if v is not None and math.isfinite(v)}
    return out


def evaluate_checkpoint(checkpoint: Path, shards: Path, scenes: list[str] | None, out_dir: Path,
                        n_source: int = 8, stride: int = 1, tracking_uri: str | None = None,
                        experiment: str = "sray-eval", *, tracker: str = DEFAULT_TRACKER, device: str | None = None,
                        progress: bool = True, fast: FastRender | None = None, runtime: Runtime = Runtime()) -> dict:
    """:func:`evaluate_model` of an S-Ray checkpoint (``checkpoint_model``: the fast mode with ``fast``, runtime)."""
    return evaluate_model(checkpoint_model(checkpoint, device, fast, runtime), shards, scenes, out_dir, n_source,
                          stride, tracking_uri, experiment, tracker=tracker, progress=progress)


def evaluate_model(model: EvalModel, shards: Path, scenes: list[str] | None, out_dir: Path, n_source: int = 8,
                   stride: int = 1, tracking_uri: str | None = None, experiment: str = "sray-eval", *,
                   tracker: str = DEFAULT_TRACKER, progress: bool = True) -> dict:
    """Evaluate ``model`` on ``scenes`` (default: the manifest's test scenes), tracked by ``tracker`` in its store
    ``tracking_uri`` (None: its default); the metrics.json content plus ``metrics_path``, ``out_dir`` and ``run``."""
    if stride < 1 or n_source < 1:
        raise ValueError(f"stride ({stride}) and n_source ({n_source}) must be >= 1")
    tracking = get_tracker(tracker, tracking_uri or "")
    shards, out_dir = Path(shards).resolve(), Path(out_dir).resolve()
    names, metas = select_scenes(shards, scenes)
    protocol = EvalProtocol.from_shards(shards, n_source, stride, model.inputs)
    protocol = protocol.rendered_by(model.fast)
    n_classes, ignore_id = model.n_classes, model.ignore_id
    for name in names:
        if len(metas[name]["class_names"]) != n_classes:
            raise ValueError(f"{shards / 'manifest.json'}: scene {name!r} has {len(metas[name]['class_names'])} "
                             f"classes, {model.subject} predicts {n_classes}; evaluate on data of the "
                             "label space the model was trained on")
    run = tracking.start_run(experiment, f"eval-{model.name}-{time.strftime('%Y%m%d-%H%M%S')}",
                             tags={"sray.kind": "eval", **model.tags, "sray.protocol": protocol.describe()})
    report: dict[str, Any] = {**model.record, "shards": str(shards), "protocol": protocol.to_json(),
                              "lpips": LPIPS_NOTE, "scenes": {}}
    t0 = time.perf_counter()
    with tracking.logger(run) as logger:
        logger.log_params({**model.record, "shards": str(shards), "scenes": names, "protocol": protocol.to_json()})
        bar = tqdm(total=sum(len(metas[s]["splits"]["test"]) for s in names), desc="eval views", unit="view",
                   disable=not progress)
        for name in names:
            per_view = []

            def record_view(view: ViewPrediction, scene: str = name) -> None:
                pngs = save_view_pngs(view, scene, metas[scene]["class_names"], ignore_id, out_dir)
                per_view.append({"query_id": view.query_id,
                                 "miou_per_image": float(per_image_scores([view], n_classes, ignore_id)["miou"]),
                                 "psnr_db": psnr(view.pred_rgb, view.gt_rgb), "pngs": pngs})
                bar.update(1)

            scored = score_scene(model.renderer, make_eval_samples(shards, name, split="test", n_source=n_source),
                                 n_classes, ignore_id, stride, model.chunk, model.device, model.fast,
                                 on_view=record_view)
            block = scene_blocks(scored.scores, len(scored.views))
            block["dataset_level"]["iou_per_class"] = class_ious(scored.views, n_classes, ignore_id)
            report["scenes"][name] = {**block, "views": per_view}
        bar.close()
        report["mean"] = mean_blocks(list(report["scenes"].values()))
        report["wall_s"] = time.perf_counter() - t0
        metrics_path = write_json_atomic(report, out_dir / METRICS_FILE)
        logger.log_metrics(flat_metrics(report), model.step)
        logger.log_artifact(metrics_path)
        for name in names:  # only this evaluation's scenes, whatever else the folder holds
            logger.log_artifact(out_dir / "renders" / name, f"renders/{name}")
    return {**_finite_or_none(report), "metrics_path": str(metrics_path), "out_dir": str(out_dir),
            "run": dataclasses.asdict(run)}


def mean_blocks(blocks: list[dict[str, Any]]) -> dict[str, Any]:
    """Unweighted mean over scenes of every score (each scene counts once); None for a score some scene lacks."""

    def avg(where: str, key: str) -> float | None:
        values = [b[where][key] for b in blocks]
        return None if any(v is None for v in values) else float(np.mean(values))

    scores = {k: avg(*path) for k, path in SCORE_PATHS.items()}
    return {**scene_blocks(scores, sum(b["n_views"] for b in blocks)), "n_scenes": len(blocks),
            "averaging": "unweighted mean over scenes"}


def text_cell(value: Any, fmt: str) -> str:
    """``value`` in format ``fmt``, a dash when None."""
    return "—" if value is None else format(value, fmt)


def text_table(rows: list[tuple[str, ...]]) -> list[str]:
    """Lines of a plain-text table of ``rows`` (the first, the head, ruled off), the first column left-aligned."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(v.ljust(w) if i == 0 else v.rjust(w) for i, (v, w) in enumerate(zip(r, widths))) for r in rows]
    lines.insert(1, "-" * len(lines[0]))
    return lines


def format_table(report: dict[str, Any]) -> str:
    """A plain-text table of a report: a row per scene, the mean, the protocol (SSIM only for whole images)."""
    protocol = EvalProtocol.from_json(report["protocol"])
    head = ("scene", "views", "mIoU", "total acc", "class acc", "mIoU/img", "PSNR dB", "SSIM")
    columns = len(head) if protocol.scores_ssim else len(head) - 1
    rows = [head[:columns]]
    for name, b in [*report["scenes"].items(), ("mean", report["mean"])]:
        d, c = b["dataset_level"], b["colour"]
        rows.append((name, str(b["n_views"]), text_cell(d["miou"], ".3f"), text_cell(d["total_acc"], ".3f"),
                     text_cell(d["class_avg_acc"], ".3f"), text_cell(b["per_image"]["miou"], ".3f"),
                     text_cell(c["psnr_db"], ".2f"), text_cell(c["ssim"], ".3f"))[:columns])
    lines = text_table(rows)
    lines.insert(len(lines) - 1, "-" * len(lines[0]))
    return "\n".join([*lines, f"Protocol: {protocol.describe()}"])


def coarse_logits(model: EvalModel, shards: Path, n_source: int, stride: int) -> tuple[torch.Tensor, torch.Tensor, int]:
    """(logits (N, L), labels (N,), rooms) of the coarse pass at every ``stride``-th pixel of the test views of
    every test room of ``shards``, rays no source sees (all logits -inf) left out."""
    names, _ = select_scenes(Path(shards), None)
    logits, labels = [], []
    for name in names:
        for sample in make_eval_samples(Path(shards), name, split="test", n_source=n_source):
            h, w = sample.query_label.shape
            out = render_view(model.renderer(sample), sample.query.K, sample.query.c2w, (h, w), sample.near,
                              sample.far, model.chunk, model.device, stride, None, passes=("coarse",),
                              keys=("logits",))["coarse"]["logits"].reshape(-1, model.n_classes).cpu()
            uv, _, _ = strided_pixels(h, w, stride)
            logits.append(out)
            labels.append(sample.query_label[uv[:, 1].long(), uv[:, 0].long()])
    all_logits, all_labels = torch.cat(logits), torch.cat(labels)
    seen = torch.isfinite(all_logits).all(-1)
    return all_logits[seen], all_labels[seen], len(names)


def calibrate(model: EvalModel, shards: Path, n_source: int = 8, stride: int = 4) -> dict[str, Any]:
    """The fitted temperature of ``model``'s coarse confidence on the validation shards and what it was fitted on:
    ``{"temperature", "nll_at_1", "nll_fitted", "rays", "rooms", "shards", "stride", "n_source"}``."""
    logits, labels, rooms = coarse_logits(model, shards, n_source, stride)
    temperature = fit_temperature(logits, labels, model.ignore_id)
    keep = labels != model.ignore_id
    return {"temperature": temperature, "nll_at_1": nll(logits[keep], labels[keep], 1.0),
            "nll_fitted": nll(logits[keep], labels[keep], temperature), "rays": int(keep.sum()), "rooms": rooms,
            "shards": str(Path(shards).resolve()), "stride": stride, "n_source": n_source}
