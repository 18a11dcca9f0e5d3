"""``sray bench speed-accuracy``: zero-shot mIoU and PSNR of one checkpoint against seconds per view.

Every setting renders the same views of the unseen test scenes (paired), so the accuracy each
setting gives up is measured against the full render of the same run. Settings trade accuracy for
speed along these axes: samples the fine pass evaluates (the union of coarse and resampled depths, or
the resampled ones only), source views, precision, the fast render mode (pixel stride = resolution,
fine pass only where the coarse pass is unsure) and the RGB-D mode's depth-guided samples (``rgbd``
settings render with the sources' depth, by the ``--checkpoint-rgbd`` model when one is given, else by
the main checkpoint's weights with ``model.inputs`` switched, as both modes share their parameters).
A Pareto chart (PNG) and its table go into the benchmark's section of docs/benchmarks.md: the default
set as one table, a run of chosen settings (``--settings``) as the other, each replaced by the next run
of its kind; chart and numbers are also logged to the tracker.
"""

from __future__ import annotations

import dataclasses
import os
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
from sray.jobs.bench.doc import Bench, bench_dir, record
from sray.model.config import SRayConfig
from sray.model.fast_render import FastRender
from sray.model.ray_chunks import CUDA_RENDER_RAYS
from sray.model.runtime import Runtime
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.eval.scene_scoring import score_scene
from sray.platform.eval.view_scoring import sray_renderer
from sray.platform.eval.zero_shot import select_scenes
from sray.platform.tracking.registry import get_tracker


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
    (dataset-level protocol, mean over scenes),
    s_per_view (CPU seconds of this process per view, all threads, source encoding and scoring included:
    unlike wall-clock time it does not grow when other jobs share the cores), wall_s_per_view, views, and the
    setting.
    """
    loaded = {}
    for key, path in (("main", checkpoint), ("rgbd", checkpoint_rgbd)):
        if path is not None:
            net, cfg = model_from_checkpoint(path)
            loaded[key] = (net.eval(), cfg, dataclasses.replace(net.cfg))  # the checkpoint's own model config
    names, _ = select_scenes(shards, None)
    cpu = torch.device("cpu")
    rows = []
    for st in settings:
        net, cfg, own = loaded["rgbd" if st.inputs == "rgbd" and "rgbd" in loaded else "main"]
        _apply(net, st, own)
        runtime = st.runtime()
        seconds, cpu_seconds, n_views, per_scene = 0.0, 0.0, 0, []
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
        row = {"name": st.name, "miou": 100 * sum(s["miou"] for s in per_scene) / len(per_scene),
               "psnr": sum(s["psnr"] for s in per_scene) / len(per_scene),
               "s_per_view": cpu_seconds / max(n_views, 1), "wall_s_per_view": seconds / max(n_views, 1),
               "views": n_views, "fine_samples": net.cfg.fine_samples, "setting": dataclasses.asdict(st)}
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


def table(rows: list[dict]) -> str:
    """Markdown table: mIoU and its paired difference to the first row (the default set's first is the
    unoptimised full render), PSNR, seconds per view, speed-up against the first row."""
    ref = rows[0]
    first = "reference" if ref["name"] == "full, reference path" else f"'{ref['name']}'"
    on_front = {r["name"] for r in pareto(rows)}
    lines = [f"| setting | mIoU % | Δ mIoU vs {first} (points) | PSNR dB | CPU s / view | wall s / view | "
             f"speed-up vs {first} (CPU s) | Pareto |", "|---|---:|---:|---:|---:|---:|---:|:---:|"]
    for r in rows:
        wall = f"{r['wall_s_per_view']:.2f}" if "wall_s_per_view" in r else "-"
        lines.append(f"| {r['name']} | {r['miou']:.2f} | {r['miou'] - ref['miou']:+.2f} | {r['psnr']:.2f} | "
                     f"{r['s_per_view']:.2f} | {wall} | {ref['s_per_view'] / r['s_per_view']:.1f}x | "
                     f"{'✓' if r['name'] in on_front else ''} |")
    return "\n".join(lines)


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


def run_speed_accuracy(checkpoint: Path, shards: Path, views_per_scene: int, doc: Path, tracker: str,
                       tracking_uri: str, checkpoint_rgbd: Path | None = None, names: list[str] | None = None) -> str:
    """Measure the default settings, or those ``names`` chooses (the ``rgbd`` ones by ``checkpoint_rgbd`` when
    given), write the chart and the table section, log both; returns the section."""
    title = table_title(names)
    rows = measure(Path(checkpoint), Path(shards), select_settings(names), views_per_scene,
                   checkpoint_rgbd=Path(checkpoint_rgbd) if checkpoint_rgbd else None)
    protocol = (EvalProtocol.from_shards(Path(shards), 8, 1).describe().replace("render: full", "render: per setting")
                .replace("inputs: rgb", "inputs: per setting (the checkpoint's unless the setting says rgbd)"))
    png = chart(rows, bench_dir(doc, SPEED) / ("chosen.png" if names else "default.png"), protocol)
    rgbd_by = f"`{checkpoint_rgbd}` (trained with model.inputs=rgbd)" if checkpoint_rgbd else "the same weights"
    own_fine = ", ".join(sorted({f"`fine_samples={r['fine_samples']}`" for r in rows
                                 if not r["setting"]["fine_samples"] and not r["setting"]["fast"]})) or "-"
    which = ("every test view" if views_per_scene <= 0 else "the first test view" if views_per_scene == 1 else
             f"the first {views_per_scene} test views")
    notes = (f"Checkpoint `{checkpoint}`; {which} of each unseen scene of `{shards}`, "
             f"the same views for every setting (paired); mIoU dataset-level per scene, then the mean over "
             f"scenes; CPU s / view is the CPU time this process spent (all its threads) encoding the sources, "
             f"rendering and scoring one whole view (`sray eval`'s loop), the speed measure here because other "
             f"jobs may share the cores (on a quiet "
             f"machine wall time is about CPU time / torch threads); wall s / view is shown beside it. Settings: "
             f"'full, reference path' is the unoptimised path "
             f"(`impl=reference`, chunks of {CUDA_RENDER_RAYS} rays) with "
             f"the checkpoint's samples; 'full' is the optimised path "
             f"(chunks by device: 256 rays on a CPU), equal to it "
             f"within fp32 tolerance. Both render as the checkpoint was trained ({own_fine}), as `sray eval "
             f"--render full` does; 'fine union' makes the fine pass re-evaluate the coarse depths too, 'fine new "
             f"only' evaluates the resampled depths alone. 'fast sS cC': the fast render mode "
             f"(`sray.model.fast_render`), rays every S-th pixel upsampled bilinearly, fine pass (resampled "
             f"depths only) where the coarse confidence is below C. 'rgbd': the coarse samples placed by the "
             f"sources' depth (docs/model.md, RGB-D mode), rendered by "
             f"{rgbd_by}. Protocol: {protocol}.\n\n"
             f"![speed-accuracy]({os.path.relpath(png, doc.parent)})")
    section = record(SPEED, title, table(rows), doc, notes)
    tracking = get_tracker(tracker, tracking_uri)
    run = tracking.start_run("sray-bench", f"speed-accuracy-{time.strftime('%Y%m%d-%H%M%S')}",
                             tags={"sray.kind": "bench", "sray.protocol": protocol})
    with tracking.logger(run) as logger:
        logger.log_params({"checkpoint": str(checkpoint), "checkpoint_rgbd": str(checkpoint_rgbd or checkpoint),
                           "shards": str(shards), "views_per_scene": views_per_scene})
        for i, r in enumerate(rows):
            logger.log_metrics({"miou": r["miou"], "psnr": r["psnr"], "cpu_s_per_view": r["s_per_view"],
                                "wall_s_per_view": r["wall_s_per_view"]}, i)
        logger.log_artifact(png)
    return section
