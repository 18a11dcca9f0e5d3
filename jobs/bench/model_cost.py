"""``sray bench model``: the attention stage's cost per CRA variant against dense attention and a training step's
time and memory, ratios measured in one run (how: ``probes``); ``--official-side-by-side`` adds the paper's public
code against sray's step from the ``results.json`` of the shared tool ``official_side_by_side/run.py`` (one run too)."""

from __future__ import annotations

import json
import multiprocessing
import os
import statistics
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from unittest import mock

import torch
from torch.nn.attention import SDPBackend

from sray.jobs.bench.probes import (attention_call, attention_case, attention_flops, model_config, peak_bytes,
                                    resolve_device, time_call, train_step_worker)
from sray.model.ray_chunks import train_piece_rays
from sray.platform.common.bench_doc import Bench
from sray.platform.common.doc_blocks import markdown_table

MODEL = Bench("model", "Model cost")
VARIANTS = ("full", "intra", "cross", "dense")
"""Attention variants of table 1 (``none`` has no attention cost)."""
PAPER_ATTENTION = {"rays": 1024, "samples": 64, "views": 8, "channels": 32}
"""The paper's CRA cost setting."""
PAPER_REFERENCE = "paper (GPU): CRA 5.40 GFLOPs / 4143 MB vs dense 10.25 GFLOPs / 17647 MB"
ALLOCATORS = {"default": "glibc malloc", "thp": "THP_MEM_ALLOC_ENABLE=1"}
"""CPU allocator settings a training-step row can use."""
OFFICIAL_TITLE = "Official S-Ray code against sray, same run"
SRAY_DEFAULT = "sray default (no THP)"
"""The official tool's row every ratio divides by."""


@dataclass
class _Sizes:
    """Problem sizes of one benchmark run."""

    attention: dict
    flop_rays: int
    mem_rays: int
    steps: list[dict]
    rounds: int = 2
    """Fresh processes per training-step row, the rows alternating round by round."""


def _sizes(device: torch.device, quick: bool) -> _Sizes:
    """Full (paper) sizes, or tiny ones for tests."""
    if quick:
        tiny = {"rays": 16, "coarse": 4, "fine": 4, "views": 2, "hw": (32, 32), "steps": 1}
        return _Sizes({"rays": 8, "samples": 8, "views": 4, "channels": 32}, 4, 8,
                      [dict(tiny, name="tiny", dtype="fp32", impl="reference", piece=16, fine_samples="union"),
                       dict(tiny, name="tiny", dtype="fp32", impl="fast", piece=4, fine_samples="union")], rounds=1)
    paper = {"name": "paper code config", "rays": 1024, "coarse": 64, "fine": 64, "views": 8, "hw": (240, 320),
             "steps": 3}
    small = {"name": "small CPU config", "rays": 256, "coarse": 32, "fine": 32, "views": 4, "hw": (120, 160),
             "steps": 12}  # a short step: more steps per process for a steadier median
    if device.type == "cuda":  # each precision beside its reference path; bf16 also compiled; a GPU is not shared
        gpu = dict(paper, steps=10)
        steps = [dict(gpu, dtype=d, impl=impl) for d in ("fp32", "bf16", "fp16") for impl in ("reference", "fast")]
        return _Sizes(PAPER_ATTENTION, 64, 1024, [*steps, dict(gpu, dtype="bf16", impl="fast", compile=True)], 1)
    # reference rows: the unoptimised path, the whole batch in one piece; fast rows: the defaults unless named
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
    """No decimals from 100 up, two from 1, three significant digits below."""
    return f"{x:.0f}" if x >= 100 else f"{x:.2f}" if x >= 1 else f"{x:.3g}"


def _attention_table(device: torch.device, sz: _Sizes) -> tuple[str, str, str]:
    """Table 1: FLOPs, peak memory and time of the attention stage alone, per variant."""
    a = sz.attention
    scale = a["rays"] / sz.mem_rays
    rows = {}
    for v in VARIANTS:
        module, space, valid = attention_case(v, sz.mem_rays, a["views"], a["samples"], a["channels"], device)
        fwd, both = attention_call(module, space, valid, False), attention_call(module, space, valid, True)
        rows[v] = {"gf": attention_flops(v, a, sz.flop_rays, device, False) / 1e9,
                   "gf_b": attention_flops(v, a, sz.flop_rays, device, True) / 1e9,
                   "mem_math": peak_bytes(fwd, device, SDPBackend.MATH) * scale / 2**20,
                   "mem_math_b": peak_bytes(both, device, SDPBackend.MATH) * scale / 2**20,
                   "mem_def_b": peak_bytes(both, device) * scale / 2**20,
                   "ms_b": time_call(both, device, 3) * scale * 1e3}
    d, f = rows["dense"], rows["full"]
    lines = ["| variant | GFLOPs fwd | GFLOPs fwd+bwd | FLOPs / dense | MB fwd (math) | MB fwd+bwd (math) | memory / "
             "dense (math) | MB fwd+bwd (default SDPA) | memory / dense (default) | ms fwd+bwd (default) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {v} | {_fmt(r['gf'])} | {_fmt(r['gf_b'])} | {r['gf'] / d['gf']:.3f} | {_fmt(r['mem_math'])} | "
              f"{_fmt(r['mem_math_b'])} | {r['mem_math_b'] / d['mem_math_b']:.3f} | {_fmt(r['mem_def_b'])} | "
              f"{r['mem_def_b'] / d['mem_def_b']:.3f} | {_fmt(r['ms_b'])} |" for v, r in rows.items()]
    verdict = (f"full CRA / dense: FLOPs {f['gf'] / d['gf']:.3f} (target <= 0.55), peak memory "
               f"(math backend, fwd+bwd) {f['mem_math_b'] / d['mem_math_b']:.3f} (target <= 0.25).")
    backend = "fused flash kernel" if device.type == "cpu" else "best available fused kernel"
    notes = (f"Input {a['rays']} rays x {a['samples']} samples x {a['views']} views x {a['channels']} channels, 4 "
             f"heads, pre-norm attention blocks without feed-forward. FLOPs: FlopCounterMode (matmuls only) with SDPA "
             f"on its MATH backend, counted at {sz.flop_rays} rays and scaled (every op is batched over rays; "
             f"linearity checked at half that). Memory: allocator peak above the starting level, measured at "
             f"{sz.mem_rays} rays and scaled to {a['rays']}; 'math' materialises the attention matrix (as the "
             f"paper's PyTorch attention does), 'default' is what SDPA picks here ({backend}), which never stores it, "
             f"so dense attention's memory no longer grows with (m N)^2 there. Time: median of 3, default backend, "
             f"scaled. {verdict} Reference, {PAPER_REFERENCE}.")
    return "Attention stage: CRA variants vs dense attention", "\n".join(lines), notes


def run_in_fresh_process(spec: dict) -> dict:
    """``train_step_worker(spec)`` in a newly spawned interpreter (clean peak RSS), with THP_MEM_ALLOC_ENABLE=1 for
    ``alloc='thp'`` and 0 otherwise, whatever this process's environment says (PyTorch reads it once)."""
    with mock.patch.dict(os.environ, {"THP_MEM_ALLOC_ENABLE": "1" if spec.get("alloc") == "thp" else "0"}), \
            ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(train_step_worker, spec).result()


def _row_key(spec: dict) -> tuple:
    """What identifies a training-step row across its repeated runs."""
    piece = train_piece_rays(spec.get("piece", 0), torch.device(spec.get("device", "cpu")), spec["rays"])
    return (spec["name"], spec["dtype"], spec.get("impl", "fast"), spec.get("alloc", "default"),
            model_config(spec).fine_samples, piece, bool(spec.get("compile")))


def _training_table(device: torch.device, sz: _Sizes) -> tuple[str, str, str]:
    """Table 2: seconds per training step, rays per second and peak memory per configuration, the median over
    ``sz.rounds`` fresh processes per row (rows alternating round by round, so a load change hits every row alike)."""
    runs: dict[tuple, list[dict]] = {}
    specs = [dict(spec, device=str(device)) for spec in sz.steps]
    for _ in range(sz.rounds):
        for spec in specs:
            runs.setdefault(_row_key(spec), []).append(run_in_fresh_process(spec))
    lines = ["| config | rays | rays per piece | samples (fine pass sees) | views | image | precision | impl | CPU "
             "allocator | first step s | s / step | rays / s | peak RSS GiB | GPU peak GiB | vs reference (same "
             "samples and allocator) | vs unoptimised default (reference, union, glibc) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    medians = {k: sorted(r["seconds"] for r in v)[len(v) // 2] for k, v in runs.items()}
    for i, spec in enumerate(specs):
        key = _row_key(spec)
        if any(_row_key(x) == key for x in specs[:i]):
            continue
        res, s = runs[key][0], medians[key]
        ref_key = (key[0], key[1], "reference", key[3], key[4], spec["rays"], False)
        vs_ref = f"{medians[ref_key] / s:.2f}x" if ref_key in medians and key[2] == "fast" else "-"
        base_key = (key[0], key[1], "reference", "default", "union", spec["rays"], False)
        vs_base = f"{medians[base_key] / s:.2f}x" if base_key in medians and key != base_key else "-"
        h, w = spec["hw"]
        rss = max(r["rss_bytes"] for r in runs[key])
        lines.append(f"| {spec['name']} | {spec['rays']} | {key[5]} | {spec['coarse']}+{spec['fine']} "
                     f"({model_config(spec).n_fine_total}) | {spec['views']} | {w}x{h} | {spec['dtype']} | "
                     f"{key[2]}{', compiled' if key[6] else ''} | {ALLOCATORS[key[3]]} | {res['first']:.2f} | "
                     f"{s:.2f} | {spec['rays'] / s:.0f} | {rss / 2**30:.2f} | {res['gpu_peak_bytes'] / 2**30:.2f} | "
                     f"{vs_ref} | {vs_base} |")
    notes = (
        "One step = encode the source views, render coarse + fine, semantic + photometric loss, backward, fused Adam "
        "(the optimizer training uses); synthetic scene; 'first step' is the warm-up, 's / step' the median over "
        f"{sz.rounds} fresh process(es) (rows alternating round by round) of each process's median step; peak RSS is "
        f"the process's VmHWM, torch runtime included ({res['params'] / 1e6:.2f} M parameters). impl: `runtime.impl` — "
        "`reference` is the unoptimised path of this same commit, `fast` the gathered, transpose-free one "
        "(docs/performance.md); both compute the same values (tests/test_model_fast_path.py); 'compiled': the coarse "
        "and fine networks through `torch.compile` (GPU rows; its compilation is in 'first step'). 'samples (fine pass "
        "sees)': `fine_samples` union (the fine pass re-evaluates the coarse depths, 64 + 128 = 192 evaluations per "
        "ray) or new (the model default: only the resampled ones, 64 + 64 = 128, as the official code). Rays per "
        "piece: the loss is computed over pieces of that many rays, each piece's gradient taken before the next is "
        "rendered (`runtime.train_piece`, `model/piecewise_loss.py`): the same loss and gradients as the whole batch "
        "at once (tests/test_piecewise_loss.py); the reference rows compute the whole batch in one piece. The paper's "
        "public code is compared in a run of its own beside sray's default step (`--official-side-by-side`, its own "
        "table). CPU allocator: THP_MEM_ALLOC_ENABLE=1 (read by PyTorch at start-up) backs large allocations with 2 "
        "MiB huge pages. The machine is shared: absolute times are noisy, ratios within one run are what carries over.")
    return "Training step: time and memory", "\n".join(lines), notes


def run_model_benchmark(device: str = "auto", quick: bool = False,
                        tables: tuple[str, ...] = ("attention", "train")) -> list[tuple[str, str, str]]:
    """The (title, markdown table, notes) sections of the benchmarks named in ``tables``."""
    dev = resolve_device(device)
    makers = {"attention": _attention_table, "train": _training_table}
    return [makers[t](dev, _sizes(dev, quick)) for t in tables]


def _summary(runs: list[dict]) -> dict:
    """Seconds per timed step (each process's first is its warm-up): median, range, per process; median RSS GiB."""
    timed = [t for r in runs for t in r["times"][1:]]
    return {"median": statistics.median(timed), "min": min(timed), "max": max(timed),
            "per_round": [statistics.median(r["times"][1:]) for r in runs],
            "rss_gib": statistics.median(r["rss_bytes"] for r in runs) / 2**30}


def official_side_by_side(results_json: Path) -> tuple[str, str, str]:
    """(title, table, notes): per variant the seconds per step and peak RSS, both against sray's default."""
    results = json.loads(Path(results_json).read_text())
    if SRAY_DEFAULT not in results:
        raise ValueError(f"{results_json}: no {SRAY_DEFAULT!r} row; pass the results.json that "
                         "official_side_by_side/run.py wrote")
    stats = {name: _summary(runs) for name, runs in results.items() if runs}
    base = stats[SRAY_DEFAULT]
    rows = [[name, f"{s['median']:.2f}", f"{s['min']:.2f}–{s['max']:.2f}",
             " / ".join(f"{x:.2f}" for x in s["per_round"]), f"{s['rss_gib']:.2f}",
             f"{s['median'] / base['median']:.2f}x", f"{s['rss_gib'] / base['rss_gib']:.2f}x"]
            for name, s in stats.items()]
    table = markdown_table(["variant", "median s / step", "min–max", "per-process medians", "peak RSS GiB",
                            "time / sray default", "memory / sray default"], rows)
    first = next(iter(results.values()))[0]
    processes = max(len(runs) for runs in results.values())
    notes = (f"The paper's public S-Ray code (its own renderer, losses, gradient clipping and Adam, random "
             f"inputs) and sray at the paper code config (1024 rays, 64+64 samples, 8 views, 320x240, fp32), "
             f"{processes} fresh process(es) per variant alternating round by round, one warm-up step each, "
             f"median over the timed steps; peak RSS is the process's VmHWM; torch {first.get('torch', '?')}, "
             f"{first.get('threads', '?')} threads. Made by the shared tools' `official_side_by_side/run.py "
             f"--checkout . --git-dir OFFICIAL_GIT_DIR`, which writes `OUT/ofc/runs/<stamp>/results.json`.")
    return OFFICIAL_TITLE, table, notes
