"""Measurement helpers for ``sray.jobs.bench.model_cost``: FLOP counts, peak allocations, timings, training steps.

* FLOPs: ``torch.utils.flop_counter.FlopCounterMode`` with SDPA forced onto its MATH backend, which
  decomposes attention into counted matmuls (the fused CPU flash kernel has no FLOP formula and
  would count 0). Fused kernels do the same matmul work, so the count holds for every backend.
* Peak memory: on CUDA, ``torch.cuda.max_memory_allocated`` above the level before the call; on
  CPU, the profiler's allocator trace (``profile_memory=True``): the highest "Total Allocated"
  reached during the call minus the level when it started. Both count PyTorch's allocator only
  (tensors and kernel scratch), the quantity the paper's "memory increment" reports.
* Training steps (``workloads``) run in a fresh spawned process each, so the process peak RSS they report
  (VmHWM) belongs to that configuration alone, as in the reference measurement of the paper's
  public code.
"""

from __future__ import annotations

import json
import os
import resource
import tempfile
import time
from collections.abc import Callable
from contextlib import nullcontext

import torch
from torch.nn.attention import SDPBackend, sdpa_kernel
from torch.utils.flop_counter import FlopCounterMode

from sray.model.config import SRayConfig
from sray.model.cra import CrossReprojectionAttention


def resolve_device(device: str) -> torch.device:
    """``auto`` -> cuda when available, else cpu; anything else as given."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError("sray.jobs.bench.model_cost: device 'cuda' asked for but no CUDA device is visible; "
                         "use --device cpu or auto.")
    return dev


def attention_case(
    variant: str, rays: int, views: int, samples: int, channels: int, device: torch.device, seed: int = 0
) -> tuple[CrossReprojectionAttention, torch.Tensor, torch.Tensor]:
    """A CRA module of ``variant`` and its input: space (R, m, N, C) and a validity mask (90% valid)."""
    gen = torch.Generator().manual_seed(seed)
    cfg = SRayConfig(feat_dim=channels, attention=variant, n_coarse=samples)
    torch.manual_seed(seed)
    module = CrossReprojectionAttention(cfg).to(device)
    space = torch.randn(rays, views, samples, channels, generator=gen).to(device)
    valid = (torch.rand(rays, views, samples, generator=gen) < 0.9).to(device)
    return module, space, valid


def sample_depths(rays: int, samples: int, device: torch.device) -> torch.Tensor:
    """Evenly spread normalised sample depths (R, N) in (0, 1), the position input of CRA."""
    return ((torch.arange(samples, dtype=torch.float32) + 0.5) / samples).expand(rays, samples).to(device)


def attention_call(module: CrossReprojectionAttention, space: torch.Tensor, valid: torch.Tensor,
                   backward: bool) -> Callable[[], None]:
    """A closure running the attention stage forward (and backward of its output sum)."""
    depth01 = sample_depths(space.shape[0], space.shape[2], space.device)

    def run() -> None:
        x = space.detach().requires_grad_(backward)
        with torch.set_grad_enabled(backward):
            out = module(x, valid, depth01)
            if backward:
                out.float().sum().backward()
    return run


def count_flops(fn: Callable[[], None]) -> int:
    """Matmul FLOPs of ``fn`` (forward and whatever backward it runs), SDPA on the MATH backend."""
    with sdpa_kernel(SDPBackend.MATH), FlopCounterMode(display=False) as counter:
        fn()
    return int(counter.get_total_flops())


def attention_flops(variant: str, sizes: dict, count_rays: int, device: torch.device, backward: bool) -> int:
    """FLOPs of the attention stage at ``sizes["rays"]`` rays, counted at ``count_rays`` and scaled.

    The scaling is exact because every op is batched over rays; it is checked by also counting at
    half as many rays. sizes: rays, views, samples, channels.
    """
    counts = []
    for r in (count_rays // 2, count_rays):
        module, space, valid = attention_case(variant, r, sizes["views"], sizes["samples"], sizes["channels"], device)
        counts.append(count_flops(attention_call(module, space, valid, backward)))
    if counts[1] != 2 * counts[0]:
        raise RuntimeError(f"sray.jobs.bench.probes: FLOPs of {variant} are not linear in rays ({counts}).")
    return counts[1] * sizes["rays"] // count_rays


def _cpu_peak_from_trace(path: str) -> int:
    """Peak allocator increment in a chrome trace written by a ``profile_memory=True`` profile."""
    with open(path) as f:
        events = [e["args"] for e in json.load(f)["traceEvents"]
                  if e.get("name") == "[memory]" and e["args"].get("Device Type") == 0]
    if not events:
        return 0
    start = events[0]["Total Allocated"] - events[0]["Bytes"]
    return max(int(e["Total Allocated"]) for e in events) - int(start)


def peak_bytes(fn: Callable[[], None], device: torch.device, backend: SDPBackend | None = None) -> int:
    """Peak bytes PyTorch's allocator holds during ``fn`` above its level at the start."""
    ctx = sdpa_kernel(backend) if backend is not None else nullcontext()
    if device.type == "cuda":
        torch.cuda.synchronize(device)
        before = torch.cuda.memory_allocated(device)
        torch.cuda.reset_peak_memory_stats(device)
        with ctx:
            fn()
        torch.cuda.synchronize(device)
        return int(torch.cuda.max_memory_allocated(device) - before)
    with tempfile.TemporaryDirectory() as tmp:
        trace = os.path.join(tmp, "trace.json")
        with ctx, torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU],
                                         profile_memory=True) as prof:
            fn()
        prof.export_chrome_trace(trace)
        return _cpu_peak_from_trace(trace)


def timed_runs(fn: Callable[[], None], device: torch.device, runs: int) -> list[float]:
    """Wall-clock seconds of ``runs`` consecutive calls of ``fn``."""
    times = []
    for _ in range(runs):
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        t0 = time.perf_counter()
        fn()
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        times.append(time.perf_counter() - t0)
    return times


def time_call(fn: Callable[[], None], device: torch.device, repeats: int) -> float:
    """Median wall-clock seconds of ``fn`` over ``repeats`` runs after one warm-up run."""
    times = timed_runs(fn, device, repeats + 1)[1:]
    return sorted(times)[len(times) // 2]


def peak_rss_bytes() -> int:
    """Peak resident set size of this process: VmHWM from /proc (Linux), else ``ru_maxrss``.

    ``ru_maxrss`` survives ``exec``: a spawned child would report at least its parent's RSS at the
    fork, so VmHWM (the high-water mark of this process's own address space) is preferred.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024  # kB
    except OSError:
        pass
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024  # KiB on Linux
