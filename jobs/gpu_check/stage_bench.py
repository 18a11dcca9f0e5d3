"""Stages ``bench`` (``sray bench model`` and one whole-view render's time) and ``profile`` (``sray bench profile`` of
the fast path's step in fp32 and bf16 and of a render; on a GPU also into docs/benchmarks.md's "Profiles")."""

from __future__ import annotations

import re

import torch

from sray.jobs.bench.model_cost import run_model_benchmark
from sray.jobs.bench.probes import time_call
from sray.jobs.bench.profile import run_profiles, write_profiles

from .context import CheckContext
from .report import StageResult, table_cells
from .synthetic import model, rig

TOP_ROWS = 5
"""Operators per profile kept in the report."""


def render_seconds(ctx: CheckContext, repeats: int, dtype: torch.dtype | None = None) -> float:
    """Median seconds to render one view, fp32 weights, no grad, under autocast to ``dtype`` when given."""
    net = model(ctx.samples, ctx.views, ctx.device).eval()
    sources, query = rig(ctx.views, ctx.image_hw, ctx.device)

    def render() -> None:
        with torch.no_grad(), torch.autocast(ctx.device.type, dtype=dtype or torch.float32, enabled=dtype is not None):
            src = net.encode(sources.rgb, sources.K, sources.c2w, sources.depth)
            net.render_image(src, query.K, query.c2w, ctx.image_hw, 1.0, 5.0)
    return time_call(render, ctx.device, repeats)


def run(ctx: CheckContext) -> StageResult:
    """The model benchmark's two tables, flattened into one, plus the whole-view render time."""
    rows = []
    for title, table, _notes in run_model_benchmark(device=str(ctx.device), quick=ctx.dry_run):
        header, body = table_cells(table)
        rows.extend([title, "; ".join(f"{h} {v}" for h, v in zip(header, cells))] for cells in body)
    h, w = ctx.image_hw
    seconds = {}
    for name, dtype in (("fp32", None), ("bf16", torch.bfloat16)):
        seconds[name] = render_seconds(ctx, 1 if ctx.dry_run else 5, dtype)
        rows.append(["whole-view render", f"{w}x{h}, {ctx.views} views, {ctx.samples[0]}+{ctx.samples[1]} samples, "
                     f"{name}: {seconds[name]:.3f} s/view ({1 / seconds[name]:.2f} views/s)"])
    summary = ", ".join(f"{k} {v:.3f}" for k, v in seconds.items())
    return StageResult("passed", f"render {w}x{h} s/view: {summary}", header=["benchmark", "row"], rows=rows)


def profile(ctx: CheckContext) -> StageResult:
    """Stage ``profile``: the top operators of each profile become the stage's rows."""
    sections = run_profiles(ctx.device, ("fast",), ("train", "render"), quick=ctx.dry_run,
                            step_dtypes=("fp32", "bf16"))
    if not ctx.dry_run:
        write_profiles(sections, ctx.repo / "docs" / "benchmarks.md")
    header = ["profile", "operator", "calls", "self CPU ms", "share of self time", "self CUDA ms"]
    rows, walls = [], []
    for title, table, _notes in sections:
        name = title.removeprefix("Profile: ")
        _, body = table_cells(table)
        rows.extend([name, *cells, *["-"] * (len(header) - 1 - len(cells))] for cells in body[:TOP_ROWS])
        wall = re.search(r"Wall time of the profiled call: ([0-9.]+) s", table)
        walls.append(f"{name} {wall.group(1) if wall else '?'} s")
    return StageResult("passed", "profiled wall time: " + ", ".join(walls), header=header, rows=rows)
