"""``sray bench profile``: top operators of the paper-config training step and of a whole-image render (the demo's
24+24 samples) under ``torch.profiler``, as docs/benchmarks.md's "Profiles" per device, and their ``levers``."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import torch
from torch.profiler import ProfilerActivity, profile

from sray.jobs.bench.levers import chunk_table, kernel_table, key_length_table
from sray.jobs.bench.probes import make_train_step, render_case
from sray.model.ray_chunks import CUDA_RENDER_RAYS, render_chunk_rays, train_piece_rays
from sray.platform.common.bench_doc import Bench, record

PROFILES = Bench("profile", "Profiles")
"""Where a training step's and a render's time goes (self time: in an operator, not its callees); the levers timed."""


def _top_table(prof: profile, wall_s: float, n: int = 18) -> str:
    """Markdown table of the ``n`` operators with the most self CPU time (self CUDA time where there is one)."""
    events = [e for e in prof.key_averages() if e.self_cpu_time_total > 0 or e.self_device_time_total > 0]
    cuda = any(e.self_device_time_total > 0 for e in events)
    key = (lambda e: e.self_device_time_total) if cuda else (lambda e: e.self_cpu_time_total)
    total = sum(key(e) for e in events) or 1.0
    head = "| operator | calls | self CPU ms | share of self time |" + (" self CUDA ms |" if cuda else "")
    lines = [head, "|---|---:|---:|---:|" + ("---:|" if cuda else "")]
    for e in sorted(events, key=key, reverse=True)[:n]:
        row = f"| `{e.key}` | {e.count} | {e.self_cpu_time_total / 1e3:.0f} | {100 * key(e) / total:.1f}% |"
        lines.append(row + (f" {e.self_device_time_total / 1e3:.0f} |" if cuda else ""))
    lines.append(f"\nWall time of the profiled call: {wall_s:.2f} s (profiler overhead included).")
    return "\n".join(lines)


def profile_call(fn: Callable[[], None], device: torch.device, warm_up: bool = True) -> tuple[profile, float]:
    """Run ``fn`` (after a warm-up call unless told not to) under ``torch.profiler``; the profile and its wall time."""
    if warm_up:
        fn()
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda" else [])
    with profile(activities=activities) as prof:
        t0 = time.perf_counter()
        fn()
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        wall = time.perf_counter() - t0
    return prof, wall


def run_profiles(device: torch.device, impls: tuple[str, ...], workloads: tuple[str, ...],
                 quick: bool, step_dtypes: tuple[str, ...] = ("fp32",)) -> list[tuple[str, str, str]]:
    """(title, markdown table, notes) sections: the ``train`` (in each of ``step_dtypes``) and ``render`` profiles per
    implementation, and the levers ``kernels``, ``train-kernels``, ``attention-keys`` and ``chunks`` timed."""
    step_spec = ({"rays": 16, "coarse": 4, "fine": 4, "views": 2, "hw": (32, 32)} if quick else
                 {"rays": 1024, "coarse": 64, "fine": 64, "views": 8, "hw": (240, 320)})
    render_spec = ({"coarse": 4, "fine": 4, "views": 2, "hw": (32, 48)} if quick else
                   {"coarse": 24, "fine": 24, "views": 8, "hw": (240, 320)})
    sections: list[tuple[str, str, str]] = []
    for impl in impls:
        if "train" in workloads:
            sections.extend(_profile_train(step_spec, impl, device, dtype) for dtype in step_dtypes)
        if "render" in workloads:
            sections.append(_profile_render(render_spec, impl, device))
    if "kernels" in workloads:
        rays, samples = (64, 8) if quick else (4096, 72)
        sections.append(("Render lever: attention kernels at the render's shapes", kernel_table(rays, samples),
                         f"One chunk of the render: {rays} rays, {samples} samples seen by the fine pass, 8 views, "
                         "4 heads of 8 channels, no grad, CPU; median of 2 calls after a warm-up. GFLOP/s counts "
                         "the two matmuls of attention (4 L^2 d per head)."))
    if "train-kernels" in workloads:
        rays, samples = (64, 8) if quick else (1024, 64)
        sections.append(("Training lever: attention kernels at the training step's shapes, forward + backward",
                         kernel_table(rays, samples, backward=True),
                         f"One attention stage of one pass of the paper-config training step: {rays} rays, {samples} "
                         "samples (the coarse pass, and the fine pass with `fine_samples=new`), 8 views, 4 heads of 8 "
                         "channels, CPU; forward + backward of a dense random gradient to q, k and v, median of 2 "
                         "calls after a warm-up. GFLOP/s counts the forward's two matmuls (4 L^2 d per head) and the "
                         "backward's four (2x), as 3x."))
    if "attention-keys" in workloads:
        samples, rays = ((8, 24), 16) if quick else ((16, 24, 32, 40, 48, 64, 96), 256)
        sections.append(("Attention kernel by key length: SDPA flash against sliced (CPU)",
                         key_length_table(samples, rays, repeats=1 if quick else 3),
                         f"The intra-view stage of one {rays}-ray piece (the CPU's training piece and render chunk), "
                         "8 source views, 4 heads of 8 channels, as the fast block runs it: q, k and v three linears "
                         "of (R, N, m, C) tokens, viewed as (R, m * heads, N, d); forward (a render) and forward + "
                         "backward of a dense gradient to the tokens and weights (a training step), median of 3 calls "
                         "after a warm-up. 'kernel used': `model.sliced_attention.attention`'s choice "
                         "(`SLICED_KEYS`, without a gradient only)."))
    if "chunks" in workloads:
        chunks, crop, samples = ((64, 16), (12, 16), 4) if quick else ((4800, 1024, 256, 64), (60, 80), 24)
        sections.append(("Render lever: rays per chunk",
                         "\n\n".join(chunk_table(chunks, impl, crop, samples) for impl in impls),
                         "`render_image` of an 80x60 crop of the 320x240 camera (the same field of view), 8 source "
                         "views, 24+24 samples, no grad; median of 2 renders after a warm-up."))
    return sections


def _profile_train(s: dict, impl: str, device: torch.device, dtype: str) -> tuple[str, str, str]:
    """The profile section of one training step of spec ``s`` in precision ``dtype``."""
    piece = train_piece_rays(s["rays"] if impl == "reference" else 0, device, s["rays"])  # reference: unoptimised
    prof, wall = profile_call(make_train_step(dict(s, impl=impl, device=str(device), dtype=dtype, piece=piece)),
                              device)
    title = f"Profile: training step, impl={impl}" + ("" if dtype == "fp32" else f", {dtype}")
    return (title, _top_table(prof, wall),
            f"{s['rays']} rays in pieces of {piece}, {s['coarse']}+{s['fine']} samples, {s['views']} source views, "
            f"{s['hw'][1]}x{s['hw'][0]}, {dtype}; encode + render + loss + backward + fused Adam on a synthetic "
            "scene, one warm-up step before the profiled one.")


def _profile_render(r: dict, impl: str, device: torch.device) -> tuple[str, str, str]:
    """The profile section of one whole-image render of spec ``r``."""
    chunk = CUDA_RENDER_RAYS if impl == "reference" else render_chunk_rays(0, device)  # reference: unoptimised
    prof, wall = profile_call(render_case(dict(r, impl=impl, device=str(device), chunk=chunk)), device,
                              warm_up=device.type == "cuda")
    return (f"Profile: whole-image render, impl={impl}", _top_table(prof, wall),
            f"`render_image` of one {r['hw'][1]}x{r['hw'][0]} view, {r['views']} source views, "
            f"{r['coarse']}+{r['fine']} samples (the demo's model size), no grad, chunks of {chunk} rays; no "
            "warm-up render on CPU (nothing to compile, and one render is minutes).")


def write_profiles(sections: list[tuple[str, str, str]], doc: Path) -> None:
    """Record each profile table in ``doc``'s "Profiles" section of this device (same-title tables replaced)."""
    for title, table, notes in sections:
        record(PROFILES, title, table, doc, notes)
