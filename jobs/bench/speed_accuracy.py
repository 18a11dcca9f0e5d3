"""``sray bench speed-accuracy``: the settings, their paired measurement (each renders the views the full render of
the same run renders) and the table; other methods' zero-shot models (``speed_methods``) are rows on the views of
S-Ray's row of their inputs, every row scored per class (``speed_classes``); the rule: ``render_default``."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.jobs.bench.render_default import DefaultChoice
from sray.jobs.bench.speed_classes import class_scores
from sray.jobs.bench.speed_store import row_key, store_rows, stored_rows
from sray.model.config import SRayConfig
from sray.model.fast_render import FastRender
from sray.model.ray_chunks import CUDA_RENDER_RAYS
from sray.model.runtime import Runtime
from sray.model.view_render import RayRenderer
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.common.bench_doc import Bench
from sray.platform.common.eval_protocol import inputs_name
from sray.platform.eval.eval_model import EvalModel
from sray.platform.eval.view_scoring import scene_confusion, score_scene, sray_renderer
from sray.platform.eval.zero_shot import select_scenes
from sray.platform.finetune.methods.sray_method import NAME as SRAY


@dataclass(frozen=True)
class Setting:
    """One point of the chart: how the views are rendered (``""``: as the checkpoint does)."""

    name: str
    n_source: int = 8
    fine_samples: str = ""
    """``SRayConfig.fine_samples``: ``union`` (the fine pass re-evaluates the coarse depths too) or ``new``."""
    fast: FastRender | None = None
    bf16: bool = False
    impl: str = "fast"
    """``Runtime.impl``: ``reference`` is the unoptimised first implementation."""
    chunk: int = 0
    """Rays per render chunk; 0 = by device (``sray.model.ray_chunks``)."""
    sample_scale: float = 1.0
    """Coarse and fine samples per ray as a fraction of the checkpoint's."""
    inputs: str = ""
    """``model.inputs``: ``rgbd`` places the coarse samples by the sources' depth."""

    def runtime(self) -> Runtime:
        """The ``Runtime`` the views are rendered with."""
        return Runtime(impl=self.impl, chunk=self.chunk)

    def same_evaluation(self, other: Setting) -> bool:
        """Whether the settings differ at most in how they render (full or fast, implementation, chunk), so either may
        stand in for the other as a default render: the same sources, inputs, samples and precision."""
        return dataclasses.replace(self, name=other.name, fast=other.fast, impl=other.impl, chunk=other.chunk) == other


def default_settings() -> list[Setting]:
    """The unoptimised full render (the reference point), the lossless fast path and the settings traded against it."""
    return [
        Setting("full, reference path", impl="reference", chunk=CUDA_RENDER_RAYS),
        Setting("full"),
        Setting("full, half the samples", sample_scale=0.5),
        Setting("full, fine union", fine_samples="union"),
        Setting("full, fine new only", fine_samples="new"),
        Setting("full, 4 sources", n_source=4),
        Setting("full, bf16", bf16=True),
        Setting("fast s1 c0.9", fast=FastRender(pixel_stride=1, confidence=0.9)),
        Setting("fast s2 c0.9", fast=FastRender(pixel_stride=2, confidence=0.9)),
        Setting("fast s4 c0.9", fast=FastRender(pixel_stride=4, confidence=0.9)),
        Setting("fast s4 c0.7", fast=FastRender(pixel_stride=4, confidence=0.7)),
        Setting("fast s8 c0.9", fast=FastRender(pixel_stride=8, confidence=0.9)),
        Setting("fast s4 c0.9, 4 sources", n_source=4, fast=FastRender(pixel_stride=4, confidence=0.9)),
        Setting("full, rgbd", inputs="rgbd"),
        Setting("full, rgbd, half the samples", inputs="rgbd", sample_scale=0.5),
    ]


SPEED = Bench("speed-accuracy", "Speed against accuracy")
DEFAULT_TABLE, CHOSEN_TABLE = "Default settings", "Chosen settings"
"""The section's two tables: the whole default set, and the latest run of chosen settings."""


def select_settings(names: list[str] | None) -> list[Setting]:
    """The default settings named in ``names``, in that order (None or empty: all); the first is the reference."""
    settings = {st.name: st for st in default_settings()}
    if not names:
        return list(settings.values())
    unknown = [n for n in names if n not in settings]
    if unknown:
        raise ValueError(f"sray bench speed-accuracy --settings: unknown {unknown}; choose from {list(settings)}.")
    return [settings[n] for n in names]


def table_title(names: list[str] | None) -> str:
    """``DEFAULT_TABLE`` for the default set, else ``CHOSEN_TABLE`` (its command names the settings)."""
    return CHOSEN_TABLE if names else DEFAULT_TABLE


def paired_settings(settings: list[Setting], inputs: Iterable[str]) -> list[Setting]:
    """``settings`` plus ``full, <inputs>`` for each of ``inputs`` none names (methods reading them go beside it)."""
    named = {st.inputs for st in settings}
    return [*settings, *(Setting(f"full, {x}", n_source=settings[0].n_source, inputs=x)
                         for x in dict.fromkeys(inputs) if x not in named)]


def twin(settings: list[Setting], inputs: str) -> Setting:
    """The last setting naming ``inputs``: a method reading them is listed after it and scored like it."""
    named = [st for st in settings if st.inputs == inputs]
    if not named:
        raise ValueError(f"speed-accuracy: no setting renders S-Ray with inputs {inputs!r}, the row a method reading "
                         f"them is compared with; add one (e.g. 'full, {inputs}')")
    return named[-1]


def _views(shards: Path, n_source: int, views_per_scene: int) -> Callable[[str], list[EvalSample]]:
    """Scene -> its first ``views_per_scene`` test views (<= 0: all) with ``n_source`` sources, decoded per call."""
    def views(scene: str) -> list[EvalSample]:
        samples = list(make_eval_samples(shards, scene, split="test", n_source=n_source))
        return samples[:views_per_scene] if views_per_scene > 0 else samples

    return views


def timed_scores(renderer: Callable[[EvalSample], RayRenderer], scenes: list[str],
                 views: Callable[[str], list[EvalSample]], n_classes: int, ignore_id: int, chunk: int,
                 fast: FastRender | None, device: torch.device,
                 context: Callable[[], AbstractContextManager] = nullcontext) -> dict[str, Any]:
    """Render and score the ``views`` of ``scenes`` with ``renderer`` inside ``context``, timed: miou and psnr
    (dataset-level per scene, mean over scenes), class_iou and class_share (one confusion matrix over every view),
    s_per_view (CPU seconds of this process), wall_s_per_view and views. Decoding the shards is not timed."""
    seconds, cpu_seconds, per_scene, conf, n_views = 0.0, 0.0, [], 0, 0
    for scene in scenes:
        samples = views(scene)
        t0, c0 = time.perf_counter(), time.process_time()
        with context():
            scored = score_scene(renderer, samples, n_classes, ignore_id, 1, chunk, device, fast)
        seconds += time.perf_counter() - t0
        cpu_seconds += time.process_time() - c0
        per_scene.append(scored.scores)
        conf = conf + scene_confusion(scored.views, n_classes, ignore_id)
        n_views += len(scored.views)
    # the last class of the matrix counts pixels without prediction: misses of their true class, never a class
    class_iou, class_share = (v[:n_classes] for v in class_scores(conf))
    return {"miou": 100 * sum(s["miou"] for s in per_scene) / len(per_scene),
            "psnr": sum(s["psnr"] for s in per_scene) / len(per_scene), "s_per_view": cpu_seconds / max(n_views, 1),
            "wall_s_per_view": seconds / max(n_views, 1), "views": n_views, "class_iou": class_iou,
            "class_share": class_share}


def measure(checkpoint: Path, shards: Path, settings: list[Setting], views_per_scene: int,
            progress: bool = True, checkpoint_rgbd: Path | None = None,
            others: dict[str, EvalModel] | None = None, store: Path | None = None) -> list[dict]:
    """One row per setting (and per method of ``others``, zero-shot models by name, each after its :func:`twin`) on
    the first ``views_per_scene`` test views of each unseen scene (<= 0: all): name, method, inputs,
    :func:`timed_scores`' values, class_names, setting and fine_samples (None for another method). ``checkpoint_rgbd``
    renders the ``rgbd`` settings (None: ``checkpoint``); ``store`` (``speed_store``): rows kept and reused."""
    loaded = {}
    for key, path in (("main", checkpoint), ("rgbd", checkpoint_rgbd)):
        if path is not None:
            net, cfg = model_from_checkpoint(path)
            loaded[key] = (net.eval(), cfg, dataclasses.replace(net.cfg))  # the checkpoint's own model config
    names, metas = select_scenes(shards, None)
    class_names, cpu = list(metas[names[0]]["class_names"]), torch.device("cpu")
    for name, model in (others or {}).items():
        if model.n_classes != len(class_names):
            raise ValueError(f"speed-accuracy: method {name}: {model.subject} predicts {model.n_classes} classes, the "
                             f"test scenes of {shards} have {len(class_names)}; give it a model of their label space")
    after = {name: twin(settings, model.inputs).name for name, model in (others or {}).items()}
    rows = []
    for st in settings:
        listed = {n: others[n].subject for n, t in after.items() if t == st.name}
        key = row_key(checkpoint, checkpoint_rgbd if st.inputs == "rgbd" else None, shards, views_per_scene, st,
                      listed)
        kept = stored_rows(store, key) if store is not None else None
        if kept is not None:
            rows.extend(kept)
            if progress:
                print(f"[speed-accuracy] {st.name}: read from {store} (measured by an earlier run)", flush=True)
            continue
        net, cfg, own = loaded["rgbd" if st.inputs == "rgbd" and "rgbd" in loaded else "main"]
        _apply(net, st, own)
        runtime, views = st.runtime(), _views(shards, st.n_source, views_per_scene)
        autocast = (lambda: torch.autocast("cpu", dtype=torch.bfloat16)) if st.bf16 else nullcontext
        scores = timed_scores(lambda s: sray_renderer(net, s, cpu, st.fast, runtime), names, views,
                              cfg.model.n_classes, cfg.model.ignore_id, runtime.chunk, st.fast, cpu, autocast)
        new = [{"name": st.name, "method": SRAY, "inputs": net.cfg.inputs, **scores, "class_names": class_names,
                "fine_samples": net.cfg.fine_samples, "setting": dataclasses.asdict(st)}]
        for name in (n for n, t in after.items() if t == st.name):
            model = others[name]
            scores = timed_scores(model.renderer, names, views, model.n_classes, model.ignore_id, model.chunk,
                                  model.fast, model.device)
            new.append({"name": name, "method": name, "inputs": model.inputs, **scores, "class_names": class_names,
                        "fine_samples": None, "setting": None})
        rows.extend(new)
        if store is not None:
            store_rows(store, key, new)
        if progress:
            for row in new:
                print(f"[speed-accuracy] {row['name']} ({inputs_name(row['inputs'])}): mIoU {row['miou']:.2f}  "
                      f"PSNR {row['psnr']:.2f}  {row['s_per_view']:.2f} CPU s/view ({row['wall_s_per_view']:.2f} s "
                      "wall)", flush=True)
    return rows


def _apply(net: torch.nn.Module, st: Setting, own: SRayConfig) -> None:
    """Put the setting's fine samples, samples per ray and inputs on the model over ``own``, the checkpoint's."""
    net.cfg.fine_samples, net.cfg.inputs = st.fine_samples or own.fine_samples, st.inputs or own.inputs
    net.cfg.n_coarse, net.cfg.n_fine = (max(1, round(n * st.sample_scale)) for n in (own.n_coarse, own.n_fine))


def pareto(rows: list[dict], cost: str = "s_per_view", score: str = "miou") -> list[dict]:
    """Rows no other row beats on both ``cost`` (lower is better) and ``score`` (higher), cheapest first."""
    front, best = [], float("-inf")
    for r in sorted(rows, key=lambda r: (r[cost], -r[score])):
        if r[score] > best:
            front.append(r)
            best = r[score]
    return front


def table(rows: list[dict], choice: DefaultChoice | None = None) -> str:
    """Markdown table of the rows against the first; with ``choice``, what the default-render rule made of each."""
    ref = rows[0]
    first = "reference" if ref["name"] == "full, reference path" else f"'{ref['name']}'"
    on_front = {r["name"] for r in pareto(rows)}
    rule = (" default rule |", ":---|") if choice is not None else ("", "")
    lines = [f"| setting or method | inputs | mIoU % | Δ mIoU vs {first} (points) | PSNR dB | CPU s / view | "
             f"wall s / view | speed-up vs {first} (CPU s) | Pareto |{rule[0]}",
             f"|---|:---|---:|---:|---:|---:|---:|---:|:---:|{rule[1]}"]
    for r in rows:
        wall = f"{r['wall_s_per_view']:.2f}" if "wall_s_per_view" in r else "-"
        verdict = ""
        if choice is not None:
            verdict = f" {'another method' if r['setting'] is None else rule_cell(r['name'], choice)} |"
        lines.append(f"| {r['name']} | {inputs_name(r['inputs'])} | {r['miou']:.2f} | {r['miou'] - ref['miou']:+.2f} | "
                     f"{r['psnr']:.2f} | {r['s_per_view']:.2f} | {wall} | {ref['s_per_view'] / r['s_per_view']:.1f}x | "
                     f"{'✓' if r['name'] in on_front else ''} |{verdict}")
    return "\n".join(lines)


def rule_cell(name: str, choice: DefaultChoice) -> str:
    """``**chosen**``, ``passes``, ``reference``, the shortfalls (``✗ chair -4.20``) or ``not offered``."""
    if name not in choice.shortfalls:
        return "not offered"
    if name == choice.chosen:
        return "**chosen**"
    if name == choice.reference:
        return "reference"
    return "passes" if choice.passes(name) else "✗ " + ", ".join(s.describe() for s in choice.shortfalls[name])
