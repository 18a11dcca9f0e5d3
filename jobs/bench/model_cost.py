"""``sray bench model``: the cost of Cross-Reprojection Attention against dense attention, and
training-step time and memory of the whole S-Ray model. Every ratio is measured in the same run.

How each number is taken is documented in ``model.bench_probes``.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import torch
from torch.nn.attention import SDPBackend

from sray.jobs.bench.probes import (
    attention_call,
    attention_case,
    attention_flops,
    peak_bytes,
    resolve_device,
    time_call,
    train_step_worker,
)

VARIANTS = ("full", "intra", "cross", "dense")
"""Attention variants compared in table 1 (``none`` has no attention cost)."""

PAPER_ATTENTION = {"rays": 1024, "samples": 64, "views": 8, "channels": 32}
"""The paper's CRA cost setting: 1024 rays x 64 samples x 8 views x 32 channels."""

PAPER_REFERENCE = "paper (GPU): CRA 5.40 GFLOPs / 4143 MB vs dense 10.25 GFLOPs / 17647 MB"
REFERENCE_CODE_STEP = (31.0, 34.0)
"""Seconds per step of the paper's public code at its configuration on the 2-core CI CPU."""


@dataclass
class _Sizes:
    """Problem sizes of one benchmark run."""

    attention: dict
    flop_rays: int
    mem_rays: int
    steps: list[dict]


def _sizes(device: torch.device, quick: bool) -> _Sizes:
    """Full (paper) sizes, or tiny ones for tests."""
    if quick:
        tiny = {"rays": 16, "coarse": 4, "fine": 4, "views": 2, "hw": (32, 32), "steps": 1}
        return _Sizes({"rays": 8, "samples": 8, "views": 4, "channels": 32}, 4, 8,
                      [dict(tiny, name="tiny", dtype="fp32")])
    paper = {"name": "paper code config", "rays": 1024, "coarse": 64, "fine": 64, "views": 8,
             "hw": (240, 320), "steps": 2}
    small = {"name": "small CPU config", "rays": 256, "coarse": 32, "fine": 32, "views": 4,
             "hw": (120, 160), "steps": 3}
    if device.type == "cuda":
        steps = [dict(paper, dtype=d, steps=10) for d in ("fp32", "bf16", "fp16")]
        return _Sizes(PAPER_ATTENTION, 64, 1024, steps)
    steps = [dict(paper, dtype="fp32"), dict(paper, dtype="fp32", alloc="thp"),
             dict(paper, dtype="fp32", alloc="thp", compile=True),
             dict(small, dtype="fp32"), dict(small, dtype="bf16")]
    return _Sizes(PAPER_ATTENTION, 64, 256, steps)


def _fmt(x: float) -> str:
    """Compact number: no decimals from 100 up, two from 1, three significant digits below."""
    return f"{x:.0f}" if x >= 100 else f"{x:.2f}" if x >= 1 else f"{x:.3g}"


def _attention_table(device: torch.device, sz: _Sizes) -> tuple[str, str, str]:
    """Table 1: FLOPs, peak memory and time of the attention stage alone, per variant."""
    a = sz.attention
    scale = a["rays"] / sz.mem_rays
    rows = {}
    for v in VARIANTS:
        module, space, valid = attention_case(v, sz.mem_rays, a["views"], a["samples"], a["channels"], device)
        fwd, both = attention_call(module, space, valid, False), attention_call(module, space, valid, True)
        rows[v] = {
            "gf": attention_flops(v, a, sz.flop_rays, device, False) / 1e9,
            "gf_b": attention_flops(v, a, sz.flop_rays, device, True) / 1e9,
            "mem_math": peak_bytes(fwd, device, SDPBackend.MATH) * scale / 2**20,
            "mem_math_b": peak_bytes(both, device, SDPBackend.MATH) * scale / 2**20,
            "mem_def_b": peak_bytes(both, device) * scale / 2**20,
            "ms_b": time_call(both, device, 3) * scale * 1e3,
        }
    d = rows["dense"]
    lines = ["| variant | GFLOPs fwd | GFLOPs fwd+bwd | FLOPs / dense | MB fwd (math) | "
             "MB fwd+bwd (math) | memory / dense (math) | MB fwd+bwd (default SDPA) | "
             "memory / dense (default) | ms fwd+bwd (default) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for v, r in rows.items():
        lines.append(f"| {v} | {_fmt(r['gf'])} | {_fmt(r['gf_b'])} | {r['gf'] / d['gf']:.3f} | "
                     f"{_fmt(r['mem_math'])} | {_fmt(r['mem_math_b'])} | "
                     f"{r['mem_math_b'] / d['mem_math_b']:.3f} | "
                     f"{_fmt(r['mem_def_b'])} | {r['mem_def_b'] / d['mem_def_b']:.3f} | {_fmt(r['ms_b'])} |")
    f = rows["full"]
    verdict = (f"full CRA / dense: FLOPs {f['gf'] / d['gf']:.3f} (target <= 0.55), peak memory "
               f"(math backend, fwd+bwd) {f['mem_math_b'] / d['mem_math_b']:.3f} (target <= 0.25).")
    backend = "fused flash kernel" if device.type == "cpu" else "best available fused kernel"
    notes = (
        f"Input {a['rays']} rays x {a['samples']} samples x {a['views']} views x {a['channels']} "
        f"channels, 4 heads, pre-norm attention blocks without feed-forward. FLOPs: "
        f"FlopCounterMode (matmuls only) with SDPA on its MATH backend, counted at {sz.flop_rays} "
        f"rays and scaled (every op is batched over rays; linearity checked at half that). Memory: "
        f"allocator peak above the starting level, measured at {sz.mem_rays} rays and scaled to "
        f"{a['rays']}; 'math' materialises the attention matrix (as the paper's PyTorch attention "
        f"does), 'default' is what SDPA picks here ({backend}), which never stores it, so dense "
        f"attention's memory no longer grows with (m N)^2 there. Time: median of 3, default backend, "
        f"scaled. {verdict} Reference, {PAPER_REFERENCE}.")
    return "S-Ray attention stage: CRA variants vs dense attention", "\n".join(lines), notes


ALLOCATORS = {"default": "glibc malloc", "thp": "THP_MEM_ALLOC_ENABLE=1"}
"""CPU allocator settings a training-step row can use."""


def _run_in_fresh_process(spec: dict) -> dict:
    """Run ``train_step_worker(spec)`` in a newly spawned interpreter (clean peak RSS).

    The child inherits THP_MEM_ALLOC_ENABLE=1 for ``alloc='thp'`` and 0 otherwise, whatever the
    caller's environment says (PyTorch reads it once, at its first allocation); the parent's
    environment is restored afterwards.
    """
    ctx = multiprocessing.get_context("spawn")
    saved = os.environ.get("THP_MEM_ALLOC_ENABLE")
    os.environ["THP_MEM_ALLOC_ENABLE"] = "1" if spec.get("alloc") == "thp" else "0"
    try:
        with ProcessPoolExecutor(max_workers=1, mp_context=ctx) as pool:
            return pool.submit(train_step_worker, spec).result()
    finally:
        if saved is None:
            os.environ.pop("THP_MEM_ALLOC_ENABLE", None)
        else:
            os.environ["THP_MEM_ALLOC_ENABLE"] = saved


def _training_table(device: torch.device, sz: _Sizes) -> tuple[str, str, str]:
    """Table 2: seconds per training step, rays per second and peak memory per configuration."""
    lines = ["| config | rays | samples | views | image | precision | CPU allocator | first step s | s / step | "
             "rays / s | peak RSS GB | GPU peak GB | speed-up vs paper code |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for spec in sz.steps:
        res = _run_in_fresh_process(dict(spec, device=str(device)))
        s = res["seconds"]
        ref = (f"{REFERENCE_CODE_STEP[0] / s:.1f}-{REFERENCE_CODE_STEP[1] / s:.1f}x"
               if spec["name"] == "paper code config" and device.type == "cpu" else "-")
        h, w = spec["hw"]
        precision = spec["dtype"] + (" + torch.compile" if spec.get("compile") else "")
        lines.append(f"| {spec['name']} | {spec['rays']} | {spec['coarse']}+{spec['fine']} | {spec['views']} | "
                     f"{w}x{h} | {precision} | {ALLOCATORS[spec.get('alloc', 'default')]} | "
                     f"{res['first']:.2f} | {s:.2f} | {spec['rays'] / s:.0f} | "
                     f"{res['rss_bytes'] / 2**30:.2f} | {res['gpu_peak_bytes'] / 2**30:.2f} | {ref} |")
    notes = (
        "One step = encode the source views, render coarse + fine, semantic + photometric loss, "
        "backward, Adam; synthetic scene; 'first step' is the warm-up (compilation included), "
        "'s / step' the median of the following steps; each "
        "configuration in a fresh process (peak RSS is that process's VmHWM, torch runtime "
        f"included; {res['params'] / 1e6:.2f} M parameters). Reference: the paper's public code "
        "takes 31-34 s per step (about 33 rays/s) and 11.8 GB peak RSS at its configuration "
        "(1024 rays, 64+64 samples, 8 views, 320x240, fp32) on this 2-core CPU. CPU allocator: "
        "glibc unmaps every freed block above 32 MiB, so each step page-faults its large "
        "temporaries in again; THP_MEM_ALLOC_ENABLE=1 (read by PyTorch at start-up) backs them "
        "with 2 MiB huge pages, 512 times fewer faults. Keeping freed memory in glibc's heap "
        "(mallopt M_MMAP_MAX=0) was tried and rejected: PyTorch's aligned requests do not fit "
        "the holes they leave, so the heap grows step after step.")
    return "S-Ray training step: time and memory", "\n".join(lines), notes


def run_model_benchmark(device: str = "auto", quick: bool = False) -> list[tuple[str, str, str]]:
    """Run both model benchmarks; returns (title, markdown table, notes) sections."""
    dev = resolve_device(device)
    sz = _sizes(dev, quick)
    return [_attention_table(dev, sz), _training_table(dev, sz)]
