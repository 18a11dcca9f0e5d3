"""``sray bench speed-accuracy``: the settings, their paired measurement, the table and the Pareto chart.

Every setting renders the same views of the unseen test scenes (paired), so the accuracy each
setting gives up is measured against the full render of the same run. Settings trade accuracy for
speed along these axes: samples the fine pass evaluates (the union of coarse and resampled depths, or
the resampled ones only), source views, precision, the fast render mode (pixel stride = resolution,
fine pass only where the coarse pass is unsure) and the RGB-D mode's depth-guided samples (``rgbd``
settings render with the sources' depth, by the ``--checkpoint-rgbd`` model when one is given, else by
the main checkpoint's weights with ``model.inputs`` switched, as both modes share their parameters).
Each setting is also scored per class (``speed_classes``), for the default-render rule (``render_default``).
The command itself, over one checkpoint or several, is ``speed_accuracy_run``.
"""

from __future__ import annotations

import dataclasses
import textwrap
import time
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

import torch
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.jobs.bench.doc import Bench
from sray.jobs.bench.render_default import DefaultChoice
from sray.jobs.bench.speed_classes import class_scores
from sray.model.config import SRayConfig
from sray.model.fast_render import FastRender
from sray.model.ray_chunks import CUDA_RENDER_RAYS
from sray.model.runtime import Runtime
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.eval.scene_scoring import score_scene
from sray.platform.eval.view_scoring import scene_confusion, sray_renderer
from sray.platform.eval.zero_shot import select_scenes


@dataclass(frozen=True)
class Setting:
    """One point of the chart: how the views are rendered."""

    name: str
    n_source: int = 8
    fine_samples: str = ""
    """``SRayConfig.fine_samples`` to render with: ``""`` the checkpoint's own (what ``sray eval --render full``
    renders), ``union`` (the fine pass re-evaluates the coarse depths too) or ``new`` (resampled depths only)."""
    fast: FastRender | None = None
    bf16: bool = False
    impl: str = "fast"
    """``Runtime.impl`` of the per-sample networks: ``reference`` is the unoptimised first implementation."""
    chunk: int = 0
    """Rays per render chunk; 0 = by device (``sray.model.ray_chunks``: 256 on a CPU)."""
    sample_scale: float = 1.0
    """Coarse and fine samples per ray as a fraction of the checkpoint's."""
    inputs: str = ""
    """``model.inputs`` to render with: ``""`` the checkpoint's own, ``rgbd`` the sources' depth places the
    coarse samples (``sray.model.depth_sampling``)."""

    def runtime(self) -> Runtime:
        """The ``Runtime`` the setting's views are rendered with: its implementation and rays per chunk."""
        return Runtime(impl=self.impl, chunk=self.chunk)

    def same_evaluation(self, other: Setting) -> bool:
        """Whether the two settings differ at most in how they render (full or fast with its stride and confidence,
        implementation, rays per chunk): the same sources, inputs, samples and precision, so either may stand in for
        the other as a default render. Fewer sources, depth inputs, other samples or bf16 change what is evaluated."""
        return dataclasses.replace(self, name=other.name, fast=other.fast, impl=other.impl, chunk=other.chunk) == other


def default_settings() -> list[Setting]:
    """The unoptimised full render (the reference point: speed-ups and mIoU differences are against it),
    the lossless fast path and the settings traded against it."""
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
"""The benchmark's section in docs/benchmarks.md."""
DEFAULT_TABLE, CHOSEN_TABLE = "Default settings", "Chosen settings"
"""The section's two tables: the whole default set, and the latest run of chosen settings."""


def select_settings(names: list[str] | None) -> list[Setting]:
    """The default settings named in ``names``, in that order (None or empty: all of them). The first is
    the row the others are compared with."""
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


def measure(checkpoint: Path, shards: Path, settings: list[Setting], views_per_scene: int,
            progress: bool = True, checkpoint_rgbd: Path | None = None) -> list[dict]:
    """Score every setting on the first ``views_per_scene`` test views of each unseen scene.

    ``checkpoint_rgbd``: the model that renders the ``inputs="rgbd"`` settings (None: ``checkpoint``'s).
    ``views_per_scene`` <= 0 scores every test view. Returns one row per setting: name, miou, psnr
    (dataset-level protocol, mean over scenes), class_iou and class_share (each class's IoU in % over every
    rendered view, None when absent, and its share of their labelled pixels: ``speed_classes.class_scores``),
    class_names,
    s_per_view (CPU seconds of this process per view, all threads, source encoding and scoring included:
    unlike wall-clock time it does not grow when other jobs share the cores), wall_s_per_view, views, and the
    setting.
    """
    loaded = {}
    for key, path in (("main", checkpoint), ("rgbd", checkpoint_rgbd)):
        if path is not None:
            net, cfg = model_from_checkpoint(path)
            loaded[key] = (net.eval(), cfg, dataclasses.replace(net.cfg))  # the checkpoint's own model config
    names, metas = select_scenes(shards, None)
    cpu = torch.device("cpu")
    rows = []
    for st in settings:
        net, cfg, own = loaded["rgbd" if st.inputs == "rgbd" and "rgbd" in loaded else "main"]
        _apply(net, st, own)
        runtime = st.runtime()
        seconds, cpu_seconds, n_views, per_scene, conf = 0.0, 0.0, 0, [], 0
        for scene in names:
            samples = list(make_eval_samples(shards, scene, split="test", n_source=st.n_source))
            samples = samples[:views_per_scene] if views_per_scene > 0 else samples
            autocast = torch.autocast("cpu", dtype=torch.bfloat16) if st.bf16 else nullcontext()
            t0, c0 = time.perf_counter(), time.process_time()
            with autocast:
                scored = score_scene(lambda s: sray_renderer(net, s, cpu, st.fast, runtime), samples,
                                     cfg.model.n_classes, cfg.model.ignore_id, 1, runtime.chunk, cpu, st.fast)
            seconds += time.perf_counter() - t0
            cpu_seconds += time.process_time() - c0
            n_views += len(scored.views)
            per_scene.append(scored.scores)
            conf = conf + scene_confusion(scored.views, cfg.model.n_classes, cfg.model.ignore_id)
        # the last class of the matrix counts pixels without prediction: misses of their true class, never a class
        class_iou, class_share = (v[:cfg.model.n_classes] for v in class_scores(conf))
        row = {"name": st.name, "miou": 100 * sum(s["miou"] for s in per_scene) / len(per_scene),
               "psnr": sum(s["psnr"] for s in per_scene) / len(per_scene),
               "s_per_view": cpu_seconds / max(n_views, 1), "wall_s_per_view": seconds / max(n_views, 1),
               "views": n_views, "fine_samples": net.cfg.fine_samples, "setting": dataclasses.asdict(st),
               "class_iou": class_iou, "class_share": class_share, "class_names": list(metas[names[0]]["class_names"])}
        rows.append(row)
        if progress:
            print(f"[speed-accuracy] {st.name}: mIoU {row['miou']:.2f}  PSNR {row['psnr']:.2f}  "
                  f"{row['s_per_view']:.2f} CPU s/view ({row['wall_s_per_view']:.2f} s wall)", flush=True)
    return rows


def _apply(net: torch.nn.Module, st: Setting, own: SRayConfig) -> None:
    """Put the setting's sampling choices on the model: fine samples, samples per ray and inputs, starting from
    ``own``, the checkpoint's model config (what a setting leaves empty keeps)."""
    net.cfg.fine_samples, net.cfg.inputs = st.fine_samples or own.fine_samples, st.inputs or own.inputs
    net.cfg.n_coarse, net.cfg.n_fine = (max(1, round(n * st.sample_scale)) for n in (own.n_coarse, own.n_fine))


def pareto(rows: list[dict], cost: str = "s_per_view", score: str = "miou") -> list[dict]:
    """Rows no other row beats on both ``cost`` (lower is better) and ``score`` (higher is better),
    cheapest first."""
    front, best = [], float("-inf")
    for r in sorted(rows, key=lambda r: (r[cost], -r[score])):
        if r[score] > best:
            front.append(r)
            best = r[score]
    return front


def table(rows: list[dict], choice: DefaultChoice | None = None) -> str:
    """Markdown table: mIoU and its paired difference to the first row (the default set's first is the
    unoptimised full render), PSNR, seconds per view, speed-up against the first row; with ``choice``, a last
    column saying what the default-render rule made of each setting (:func:`rule_cell`)."""
    ref = rows[0]
    first = "reference" if ref["name"] == "full, reference path" else f"'{ref['name']}'"
    on_front = {r["name"] for r in pareto(rows)}
    rule = (" default rule |", ":---|") if choice is not None else ("", "")
    lines = [f"| setting | mIoU % | Δ mIoU vs {first} (points) | PSNR dB | CPU s / view | wall s / view | "
             f"speed-up vs {first} (CPU s) | Pareto |{rule[0]}", f"|---|---:|---:|---:|---:|---:|---:|:---:|{rule[1]}"]
    for r in rows:
        wall = f"{r['wall_s_per_view']:.2f}" if "wall_s_per_view" in r else "-"
        verdict = f" {rule_cell(r['name'], choice)} |" if choice is not None else ""
        lines.append(f"| {r['name']} | {r['miou']:.2f} | {r['miou'] - ref['miou']:+.2f} | {r['psnr']:.2f} | "
                     f"{r['s_per_view']:.2f} | {wall} | {ref['s_per_view'] / r['s_per_view']:.1f}x | "
                     f"{'✓' if r['name'] in on_front else ''} |{verdict}")
    return "\n".join(lines)


def rule_cell(name: str, choice: DefaultChoice) -> str:
    """What the rule made of setting ``name``: ``**chosen**``, ``passes``, ``reference``, the shortfalls that
    rejected it (``✗ chair -4.20``), or ``not offered`` for a setting that evaluates otherwise (sources, inputs,
    samples, precision)."""
    if name not in choice.shortfalls:
        return "not offered"
    if name == choice.chosen:
        return "**chosen**"
    if name == choice.reference:
        return "reference"
    return "passes" if choice.passes(name) else "✗ " + ", ".join(s.describe() for s in choice.shortfalls[name])


def chart(rows: list[dict], path: Path, protocol: str) -> Path:
    """Pareto chart: mIoU (%) against CPU seconds per view (log scale), the front joined by a line. Points are
    numbered and a key beside the axes names them (names of nearby settings would overlap); the protocol is
    wrapped into the title."""
    fig = Figure(figsize=(11, 6.5))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.07, 0.1, 0.56, 0.74))
    for i, r in enumerate(rows, 1):
        ax.scatter(r["s_per_view"], r["miou"], s=40, color="tab:blue" if r["setting"]["fast"] else "tab:gray")
        ax.annotate(str(i), (r["s_per_view"], r["miou"]), textcoords="offset points", xytext=(4, 3), fontsize=8)
    front = pareto(rows)
    ax.plot([r["s_per_view"] for r in front], [r["miou"] for r in front], color="tab:orange", lw=1.5,
            label="Pareto front")
    ax.scatter([], [], color="tab:blue", label="fast render mode")
    ax.scatter([], [], color="tab:gray", label="full render")
    ax.set_xscale("log")
    ax.set_xlabel("CPU seconds per view (log scale; this process, all threads)")
    ax.set_ylabel("mIoU (%)")
    ax.grid(True, which="both", alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), loc="lower left", bbox_to_anchor=(0.655, 0.1), fontsize=8)
    key = [f"{i:>2}  {r['name']}: {r['miou']:.2f}%, {r['s_per_view']:.2f} CPU s" for i, r in enumerate(rows, 1)]
    fig.text(0.66, 0.84, "\n".join(key), va="top", ha="left", family="monospace", fontsize=8)
    title = ["S-Ray zero-shot: accuracy against render time"] + textwrap.wrap(protocol, 150)
    fig.text(0.5, 0.98, "\n".join(title), va="top", ha="center", fontsize=8)
    return save_png(fig, path, dpi=120)
