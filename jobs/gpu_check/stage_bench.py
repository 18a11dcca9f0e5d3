"""Stage ``bench``: ``sray bench model`` on this device (attention cost with the fused kernels, the
paper-config step in each precision) and the time to render one whole view."""

from __future__ import annotations

import time

import torch

from sray.jobs.bench.model_cost import run_model_benchmark

from .context import CheckContext
from .report import StageResult, table_cells
from .synthetic import model, rig


def render_seconds(ctx: CheckContext, repeats: int, dtype: torch.dtype | None = None) -> float:
    """Median seconds to render one (H, W) view from ``ctx.views`` sources, fp32 weights, no grad; under
    autocast to ``dtype`` (bf16, fp16) when given, as ``sray eval`` runs a low-precision checkpoint."""
    net = model(ctx.samples, ctx.views, ctx.device).eval()
    sources, query = rig(ctx.views, ctx.image_hw, ctx.device)
    times = []
    for _ in range(repeats + 1):
        if ctx.device.type == "cuda":
            torch.cuda.synchronize(ctx.device)
        start = time.perf_counter()
        with torch.no_grad(), torch.autocast(ctx.device.type, dtype=dtype or torch.float32, enabled=dtype is not None):
            src = net.encode(sources.rgb, sources.K, sources.c2w, sources.depth)
            net.render_image(src, query.K, query.c2w, ctx.image_hw, 1.0, 5.0)
        if ctx.device.type == "cuda":
            torch.cuda.synchronize(ctx.device)
        times.append(time.perf_counter() - start)
    rest = sorted(times[1:])
    return rest[len(rest) // 2]


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
