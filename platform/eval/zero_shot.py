"""``sray eval``: score a pretrained model on unseen scenes with the paper's generalization protocol.

The model is any registered method's :class:`~sray.platform.eval.eval_model.EvalModel`: an S-Ray checkpoint
(:func:`evaluate_checkpoint`), or ``2d-transfer``'s 2D segmenter. Every ``test`` view of a scene is rendered and
scored by the shared loop, ``scene_scoring.score_scene`` (the model's whole-view renderer in ray chunks, every
``stride``-th pixel in each direction; stride 1 = the whole image), from its ``n_source`` FIXED source views
(its top-ranked neighbours inside the scene's ``source`` split), by the pretrained model as it is: no per-scene
optimisation.

Outputs under ``out_dir``:

* ``metrics.json`` (atomic): what the model is (``EvalModel.record``: S-Ray's ``checkpoint`` and
  ``checkpoint_step``; 2d-transfer's ``method``, ``segmenter`` and ``tolerance``),
  ``protocol`` (:class:`sray.platform.common.eval_protocol.EvalProtocol`: source
  rule from the shard manifest, source views, stride, render mode, inputs), then per scene and the
  mean over scenes, in blocks that each name their metric protocol: ``dataset_level`` (mIoU, total
  and class-average accuracy from one confusion matrix per scene, and per scene each class's IoU,
  ``iou_per_class``, null for a class absent from its ground truth), ``per_image`` (mIoU per view,
  then averaged), ``colour`` (PSNR; SSIM with its window, null unless stride is 1); per-view scores;
  the LPIPS note (not computable offline);
* ``renders/<scene>/<view>_{pred,gt,error}.png`` at the render's own resolution (colours from
  :mod:`sray.platform.viz.palette`; a pixel without prediction is drawn in the unlabelled colour and counts as
  an error) and ``<view>_panel.png`` (:func:`sray.platform.viz.renders.render_panel`).

All of it goes into a new run of the chosen tracker (metrics at the checkpoint's training step, 0 for a model
without one; metrics.json and the PNGs as artifacts).
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from sray.data_tools.atomic import atomic_write_bytes, atomic_write_json
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.shards.manifest import read_manifest
from sray.model.fast_render import FastRender
from sray.model.metrics import DATASET_PROTOCOL, LPIPS_NOTE, PER_IMAGE_PROTOCOL, psnr
from sray.model.runtime import Runtime
from sray.model.ssim import SSIM_PROTOCOL, SSIM_WINDOW
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.eval.eval_model import EvalModel, checkpoint_model
from sray.platform.eval.label_transfer import UNSEEN
from sray.platform.eval.scene_scoring import score_scene
from sray.platform.eval.view_scoring import ViewPrediction, class_ious, per_image_scores
from sray.platform.tracking.registry import DEFAULT_TRACKER, get_tracker
from sray.platform.viz.palette import colorize
from sray.platform.viz.renders import error_map, render_panel

METRICS_FILE = "metrics.json"


def _finite_or_none(value: Any) -> Any:
    """JSON has no NaN: NaN/inf become null, recursively."""
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json_atomic(obj: Any, path: Path) -> Path:
    """Write ``obj`` as indented JSON (NaN as null) through a temporary name; returns ``path``."""
    atomic_write_json(Path(path), _finite_or_none(obj))
    return Path(path)


def write_png_atomic(rgb: np.ndarray, path: Path) -> Path:
    """Write a uint8 (H, W, 3) RGB image as PNG through a temporary name; returns ``path``."""
    ok, data = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:
        raise OSError(f"{path}: OpenCV could not encode a {rgb.shape} {rgb.dtype} image as PNG")
    atomic_write_bytes(Path(path), data.tobytes())
    return Path(path)


def training_scenes(shards: Path, count: int) -> list[str]:
    """The first ``count`` training scenes of ``shards`` by name (``role`` "train", or none given): the scenes whose
    held-out (``test``) views measure fitting with the zero-shot protocol. ValueError when ``count`` < 1."""
    if count < 1:
        raise ValueError(f"{Path(shards) / 'manifest.json'}: {count} held-out training scenes asked for; ask for 1 "
                         "or more")
    manifest = read_manifest(Path(shards))
    return sorted(s for s, e in manifest.scenes.items() if e.meta.get("role", "train") == "train")[:count]


def select_scenes(shards: Path, scenes: list[str] | None) -> tuple[list[str], dict[str, dict]]:
    """The scenes to evaluate (default: every ``role == "test"`` scene) and their metadata.

    ValueError names the manifest and the fix for unknown scenes or scenes without ``test`` views.
    """
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
    """Predicted / ground-truth semantics, error map and the combined panel of one view, written
    under ``out_dir/renders/<scene>/``. Returns {kind: path relative to ``out_dir``}."""
    gt = view.gt_label.numpy()
    pred = np.where(view.pred_label.numpy() == UNSEEN, ignore_id, view.pred_label.numpy())  # no prediction: blank
    n = len(class_names)
    stem = out_dir / "renders" / scene / str(view.query_id)
    files = {
        "pred": write_png_atomic(colorize(pred, n, ignore_id), stem.with_name(f"{stem.name}_pred.png")),
        "gt": write_png_atomic(colorize(gt, n, ignore_id), stem.with_name(f"{stem.name}_gt.png")),
        "error": write_png_atomic(error_map(view.pred_label.numpy(), gt, ignore_id),
                                  stem.with_name(f"{stem.name}_error.png")),
        "panel": render_panel(pred, gt, view.pred_rgb.numpy(), view.gt_rgb.numpy(), class_names,
                              stem.with_name(f"{stem.name}_panel.png"), ignore_id,
                              title=f"zero-shot: {scene} view {view.query_id}"),
    }
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


def view_scores(view: ViewPrediction, n_classes: int, ignore_id: int) -> dict[str, float]:
    """Per-image mIoU and PSNR of one view."""
    miou = per_image_scores([view], n_classes, ignore_id)["miou"]
    return {"miou_per_image": float(miou), "psnr_db": psnr(view.pred_rgb, view.gt_rgb)}


def flat_metrics(report: dict[str, Any]) -> dict[str, float]:
    """Tracked metric keys ``<scene or mean>/<metric>`` of a metrics.json report (finite values only)."""
    out = {}
    for name, block in [*report["scenes"].items(), ("mean", report["mean"])]:
        values = {"miou": block["dataset_level"]["miou"], "total_acc": block["dataset_level"]["total_acc"],
                  "class_avg_acc": block["dataset_level"]["class_avg_acc"],
                  "miou_per_image": block["per_image"]["miou"], "psnr": block["colour"]["psnr_db"],
                  "ssim": block["colour"]["ssim"]}
        out |= {f"{name}/{k}": float(v) for k, v in values.items() if v is not None and math.isfinite(v)}
    return out


def evaluate_checkpoint(checkpoint: Path, shards: Path, scenes: list[str] | None, out_dir: Path,
                        n_source: int = 8, stride: int = 1, tracking_uri: str | None = None,
                        experiment: str = "sray-eval", *, tracker: str = DEFAULT_TRACKER, device: str | None = None,
                        progress: bool = True, fast: FastRender | None = None, runtime: Runtime = Runtime()) -> dict:
    """:func:`evaluate_model` of the S-Ray checkpoint ``checkpoint`` (``eval_model.checkpoint_model``).

    ``fast``: render with the fast render mode (``sray.model.fast_render``) instead of the full
    renderer; the protocol's ``render`` field names it with its settings. ``runtime``: the implementation and
    rays per chunk the network runs with (default: the fast path, chunks by device).
    """
    return evaluate_model(checkpoint_model(checkpoint, device, fast, runtime), shards, scenes, out_dir, n_source,
                          stride, tracking_uri, experiment, tracker=tracker, progress=progress)


def evaluate_model(model: EvalModel, shards: Path, scenes: list[str] | None, out_dir: Path, n_source: int = 8,
                   stride: int = 1, tracking_uri: str | None = None, experiment: str = "sray-eval", *,
                   tracker: str = DEFAULT_TRACKER, progress: bool = True) -> dict:
    """Evaluate ``model`` on ``scenes`` (default: the manifest's test scenes); see the module doc.

    Returns the metrics.json content plus ``metrics_path``, ``out_dir`` and ``run`` (the fields of the
    run's :class:`~sray.platform.tracking.tracker.RunHandle`: tracker, store, run id, experiment id,
    UI url and hint). ``tracker``: a registry name; ``tracking_uri``: its store (None = the tracker's
    default store in the working directory).
    """
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
                per_view.append({"query_id": view.query_id, **view_scores(view, n_classes, ignore_id), "pngs": pngs})
                bar.update(1)

            scored = score_scene(model.renderer, make_eval_samples(shards, name, split="test", n_source=n_source),
                                 n_classes, ignore_id, stride, model.chunk, model.device, model.fast,
                                 on_view=record_view)
            block = scene_blocks(scored.scores, len(scored.views))
            block["dataset_level"]["iou_per_class"] = class_ious(scored.views, n_classes, ignore_id)
            report["scenes"][name] = {**block, "views": per_view}
        bar.close()
        scene_scores = [report["scenes"][n] for n in names]
        report["mean"] = mean_blocks(scene_scores)
        report["wall_s"] = time.perf_counter() - t0
        metrics_path = write_json_atomic(report, out_dir / METRICS_FILE)
        logger.log_metrics(flat_metrics(_finite_or_none(report)), model.step)
        logger.log_artifact(metrics_path)
        for name in names:  # only this evaluation's scenes, whatever else the folder holds
            logger.log_artifact(out_dir / "renders" / name, f"renders/{name}")
    return {**_finite_or_none(report), "metrics_path": str(metrics_path), "out_dir": str(out_dir),
            "run": dataclasses.asdict(run)}


def mean_blocks(blocks: list[dict[str, Any]]) -> dict[str, Any]:
    """Unweighted mean over scenes of every score (each scene counts once, whatever its view count).

    A score some scene lacks (SSIM of strided renders) has no mean: None.
    """

    def avg(path: tuple[str, str]) -> float | None:
        values = [b[path[0]][path[1]] for b in blocks]
        return None if any(v is None for v in values) else float(np.mean(values))

    scores = {"miou": avg(("dataset_level", "miou")), "total_acc": avg(("dataset_level", "total_acc")),
              "class_avg_acc": avg(("dataset_level", "class_avg_acc")), "miou_per_image": avg(("per_image", "miou")),
              "psnr": avg(("colour", "psnr_db")), "ssim": avg(("colour", "ssim"))}
    return {**scene_blocks(scores, sum(b["n_views"] for b in blocks)), "n_scenes": len(blocks),
            "averaging": "unweighted mean over scenes"}


def format_table(report: dict[str, Any]) -> str:
    """A plain-text table of a report: one row per scene, then the mean, the protocol line below.

    The SSIM column is there only for whole-image evaluations (stride 1).
    """
    protocol = EvalProtocol.from_json(report["protocol"])
    head = ("scene", "views", "mIoU", "total acc", "class acc", "mIoU/img", "PSNR dB", "SSIM")
    columns = len(head) if protocol.scores_ssim else len(head) - 1
    rows = [head[:columns]]

    def cell(v: Any, fmt: str) -> str:
        return "—" if v is None else format(v, fmt)

    for name, b in [*report["scenes"].items(), ("mean", report["mean"])]:
        d, c = b["dataset_level"], b["colour"]
        rows.append((name, str(b["n_views"]), cell(d["miou"], ".3f"), cell(d["total_acc"], ".3f"),
                     cell(d["class_avg_acc"], ".3f"), cell(b["per_image"]["miou"], ".3f"),
                     cell(c["psnr_db"], ".2f"), cell(c["ssim"], ".3f"))[:columns])
    widths = [max(len(r[i]) for r in rows) for i in range(columns)]
    lines = ["  ".join(v.ljust(w) if i == 0 else v.rjust(w) for i, (v, w) in enumerate(zip(r, widths))) for r in rows]
    lines.insert(1, "-" * len(lines[0]))
    lines.insert(len(lines) - 1, "-" * len(lines[0]))
    return "\n".join([*lines, f"Protocol: {protocol.describe()}"])
