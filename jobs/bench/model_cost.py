"""``sray bench model``: the cost of Cross-Reprojection Attention against dense attention, and
training-step time and memory of the whole S-Ray model. Every ratio is measured in the same run.

How each number is taken is documented in ``sray.jobs.bench.probes``.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import torch
from torch.nn.attention import SDPBackend

from sray.platform.common.bench_doc import Bench
from sray.jobs.bench.probes import (
    attention_call,
    attention_case,
    attention_flops,
    peak_bytes,
    resolve_device,
    time_call,
)
from sray.jobs.bench.workloads import model_config, train_step_worker
from sray.model.ray_chunks import train_piece_rays

MODEL = Bench("model", "Model cost")
"""The benchmark's section in docs/benchmarks.md."""

VARIANTS = ("full", "intra", "cross", "dense")
"""Attention variants compared in table 1 (``none`` has no attention cost)."""

PAPER_ATTENTION = {"rays": 1024, "samples": 64, "views": 8, "channels": 32}
"""The paper's CRA cost setting: 1024 rays x 64 samples x 8 views x 32 channels."""

PAPER_REFERENCE = "paper (GPU): CRA 5.40 GFLOPs / 4143 MB vs dense 10.25 GFLOPs / 17647 MB"
REPEATS = 2
"""Fresh processes per training-step row, run alternately with the other rows (rounds)."""


@dataclass
class _Sizes:
    """Problem sizes of one benchmark run."""

    attention: dict
    flop_rays: int
    mem_rays: int
    steps: list[dict]
    rounds: int = REPEATS
    """Fresh processes per training-step row, the rows alternating round by round (1: each row once)."""


def _sizes(device: torch.device, quick: bool) -> _Sizes:
    """Full (paper) sizes, or tiny ones for tests."""
    if quick:
        tiny = {"rays": 16, "coarse": 4, "fine": 4, "views": 2, "hw": (32, 32), "steps": 1}
        return _Sizes({"rays": 8, "samples": 8, "views": 4, "channels": 32}, 4, 8,
                      [dict(tiny, name="tiny", dtype="fp32", impl="reference", piece=16, fine_samples="union"),
                       dict(tiny, name="tiny", dtype="fp32", impl="fast", piece=4, fine_samples="union")], rounds=1)
    paper = {"name": "paper code config", "rays": 1024, "coarse": 64, "fine": 64, "views": 8,
             "hw": (240, 320), "steps": 3}
    small = {"name": "small CPU config", "rays": 256, "coarse": 32, "fine": 32, "views": 4,
             "hw": (120, 160), "steps": 12}  # a 0.3 s step: more steps per process for a steadier median
    if device.type == "cuda":
        # each precision beside its reference path; bf16 also compiled (the CUDA target precision)
        gpu = dict(paper, steps=10)
        steps = [dict(gpu, dtype=d, impl=impl) for d in ("fp32", "bf16", "fp16") for impl in ("reference", "fast")]
        steps.append(dict(gpu, dtype="bf16", impl="fast", compile=True))
        return _Sizes(PAPER_ATTENTION, 64, 1024, steps, rounds=1)  # a GPU is not shared: one round
    # reference rows: the unoptimised path, the whole batch in one piece; fast rows: the defaults (pieces by
    # device, fine_samples new) unless a whole-batch piece or the union is named
    whole, whole_small, union = {"piece": paper["rays"]}, {"piece": small["rays"]}, {"fine_samples": "union"}
    steps = [dict(paper, dtype="fp32", impl="reference", **union, **whole),
             dict(paper, dtype="fp32", impl="fast", **union),
             dict(paper, dtype="fp32", impl="reference", **whole),
             dict(paper, dtype="fp32", impl="fast", **whole),
             dict(paper, dtype="fp32", impl="fast"),
             dict(paper, dtype="fp32", impl="fast", alloc="thp"),
             dict(small, dtype="fp32", impl="reference", **union, **whole_small),
             dict(small, dtype="fp32", impl="fast", **union),
             dict(small, dtype="fp32", impl="reference", **whole_small),
             dict(small, dtype="fp32", impl="fast"),
             dict(small, dtype="bf16", impl="fast")]
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
    return "Attention stage: CRA variants vs dense attention", "\n".join(lines), notes


ALLOCATORS = {"default": "glibc malloc", "thp": "THP_MEM_ALLOC_ENABLE=1"}
"""CPU allocator settings a training-step row can use."""


def run_in_fresh_process(spec: dict) -> dict:
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


def _row_key(spec: dict) -> tuple:
    """What identifies a training-step row across its repeated runs."""
    return (spec["name"], spec["dtype"], spec.get("impl", "fast"), spec.get("alloc", "default"),
            model_config(spec).fine_samples, _piece(spec), bool(spec.get("compile")))


def _piece(spec: dict) -> int:
    """Rays per piece of the row's training loss (``ray_chunks.train_piece_rays`` of its setting)."""
    return train_piece_rays(spec.get("piece", 0), torch.device(spec.get("device", "cpu")), spec["rays"])


def _training_table(device: torch.device, sz: _Sizes) -> tuple[str, str, str]:
    """Table 2: seconds per training step, rays per second and peak memory per configuration.

    Every row runs ``sz.rounds`` times in fresh processes, the rows alternating round by round, so a
    load change on the machine hits every row alike; the table shows the median over the rounds.
    """
    runs: dict[tuple, list[dict]] = {}
    specs = [dict(spec, device=str(device)) for spec in sz.steps]
    for _ in range(sz.rounds):
        for spec in specs:
            runs.setdefault(_row_key(spec), []).append(run_in_fresh_process(spec))
    lines = ["| config | rays | rays per piece | samples (fine pass sees) | views | image | precision | impl | "
             "CPU allocator | first step s | "
             "s / step | rays / s | peak RSS GiB | GPU peak GiB | vs reference (same samples and allocator) | "
             "vs unoptimised default (reference, union, glibc) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    medians = {k: sorted(r["seconds"] for r in v)[len(v) // 2] for k, v in runs.items()}
    for i, spec in enumerate(specs):
        key = _row_key(spec)
        if key not in runs or any(_row_key(x) == key for x in specs[:i]):
            continue
        res, s = runs[key][0], medians[key]
        ref_key = (key[0], key[1], "reference", key[3], key[4], spec["rays"], False)
        vs_ref = f"{medians[ref_key] / s:.2f}x" if ref_key in medians and key[2] == "fast" else "-"
        base_key = (key[0], key[1], "reference", "default", "union", spec["rays"], False)
        vs_base = f"{medians[base_key] / s:.2f}x" if base_key in medians and key != base_key else "-"
        alloc = spec.get("alloc", "default")
        h, w = spec["hw"]
        fine = model_config(spec).n_fine_total
        rss = max(r["rss_bytes"] for r in runs[key])
        lines.append(f"| {spec['name']} | {spec['rays']} | {key[5]} | {spec['coarse']}+{spec['fine']} ({fine}) | "
                     f"{spec['views']} | "
                     f"{w}x{h} | {spec['dtype']} | {key[2]}{', compiled' if key[6] else ''} | {ALLOCATORS[alloc]} | "
                     f"{res['first']:.2f} | {s:.2f} | {spec['rays'] / s:.0f} | "
                     f"{rss / 2**30:.2f} | {res['gpu_peak_bytes'] / 2**30:.2f} | {vs_ref} | {vs_base} |")
    notes = (
        "One step = encode the source views, render coarse + fine, semantic + photometric loss, "
        "backward, fused Adam (the optimizer training uses); synthetic scene; 'first step' is the warm-up, "
        "'s / step' the median over "
        f"{sz.rounds} fresh process(es) (rows alternating round by round) of each process's median step; "
        "peak RSS is the process's VmHWM, torch runtime included "
        f"({res['params'] / 1e6:.2f} M parameters). impl: `runtime.impl` — `reference` is the unoptimised "
        "path of this same commit, `fast` the gathered, transpose-free one (docs/performance.md); both compute "
        "the same values (tests/test_model_fast_path.py); 'compiled': the coarse and fine networks through "
        "`torch.compile` (GPU rows; its compilation is in 'first step'). 'samples (fine pass sees)': "
        "`fine_samples` union "
        "(the fine pass re-evaluates the coarse depths, 64 + 128 = 192 evaluations per ray) or new (the model "
        "default: only the resampled ones, 64 + 64 = 128, as the official code). Rays per piece: the loss is "
        "computed over pieces of that many rays, each piece's gradient taken before the next is rendered "
        "(`runtime.train_piece`, "
        "`model/piecewise_loss.py`): the same loss and gradients as the whole batch at once "
        "(tests/test_piecewise_loss.py); the reference rows compute the whole batch in one piece. "
        "The paper's public code is compared in a run of its own beside sray's default step "
        "(`--official-side-by-side`, its own table). CPU allocator: THP_MEM_ALLOC_ENABLE=1 (read by "
        "PyTorch at start-up) backs large allocations with 2 MiB huge pages. The machine is shared: absolute "
        "times are noisy, ratios within one run are what carries over.")
    return "Training step: time and memory", "\n".join(lines), notes


def run_model_benchmark(device: str = "auto", quick: bool = False,
                        tables: tuple[str, ...] = ("attention", "train")) -> list[tuple[str, str, str]]:
    """Run the model benchmarks named in ``tables`` (attention cost, training step); returns (title,
    markdown table, notes) sections."""
    dev = resolve_device(device)
    sz = _sizes(dev, quick)
    makers = {"attention": _attention_table, "train": _training_table}
    return [makers[t](dev, sz) for t in tables]
