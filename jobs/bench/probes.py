"""Measurement helpers for ``sray.jobs.bench.model_cost``: FLOP counts, peak allocations, timings, training steps.

* FLOPs: ``torch.utils.flop_counter.FlopCounterMode`` with SDPA forced onto its MATH backend, which
  decomposes attention into counted matmuls (the fused CPU flash kernel has no FLOP formula and
  would count 0). Fused kernels do the same matmul work, so the count holds for every backend.
* Peak memory: on CUDA, ``torch.cuda.max_memory_allocated`` above the level before the call; on
  CPU, the profiler's allocator trace (``profile_memory=True``): the highest "Total Allocated"
  reached during the call minus the level when it started. Both count PyTorch's allocator only
  (tensors and kernel scratch), the quantity the paper's "memory increment" reports.
* Training steps run in a fresh spawned process each, so the process peak RSS they report
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


def _timed_runs(fn: Callable[[], None], device: torch.device, runs: int) -> list[float]:
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
    times = _timed_runs(fn, device, repeats + 1)[1:]
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


def _synthetic_batch(rays: int, views: int, hw: tuple[int, int], device: torch.device) -> dict:
    """Random source images and a camera rig whose sources all look at the query's frustum."""
    from sray.model.rays import pixel_rays

    h, w = hw
    gen = torch.Generator().manual_seed(0)
    K = torch.tensor([[w / 2, 0.0, (w - 1) / 2], [0.0, w / 2, (h - 1) / 2], [0.0, 0.0, 1.0]])
    c2w = torch.eye(4).repeat(views, 1, 1)
    c2w[:, 0, 3] = torch.linspace(-0.3, 0.3, views)
    c2w[:, 1, 3] = 0.1 * torch.sin(torch.arange(views, dtype=torch.float32))
    uv = torch.rand(rays, 2, generator=gen) * torch.tensor([w - 1.0, h - 1.0])
    origins, dirs = pixel_rays(K, torch.eye(4), uv)
    batch = {"src_rgb": torch.rand(views, 3, h, w, generator=gen), "src_K": K.expand(views, 3, 3).clone(),
             "src_c2w": c2w, "origins": origins, "dirs": dirs,
             "label": torch.randint(0, 20, (rays,), generator=gen), "rgb": torch.rand(rays, 3, generator=gen)}
    return {k: v.to(device) for k, v in batch.items()}


def train_step_worker(spec: dict) -> dict:
    """Time full training steps (encode, render, loss, backward, Adam) for one configuration.

    spec: rays, coarse, fine, views, hw, device, dtype ('fp32'|'bf16'|'fp16'), steps, and
    optionally compile (compile both per-sample fields with ``torch.compile`` in place) and
    alloc ('thp' needs the environment variable THP_MEM_ALLOC_ENABLE=1 set by the parent before
    this process starts).
    Meant to run in a fresh process; returns the first step's time (warm-up, compilation
    included), the median of the following ``steps`` steps and the process peak RSS.
    """
    from sray.model.losses import render_loss
    from sray.model.semantic_ray import SRayModel

    device = torch.device(spec["device"])
    torch.manual_seed(0)
    cfg = SRayConfig(n_coarse=spec["coarse"], n_fine=spec["fine"], n_source=spec["views"])
    model = SRayModel(cfg).to(device)
    if spec.get("compile"):
        model.coarse.compile()
        model.fine.compile()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    batch = _synthetic_batch(spec["rays"], spec["views"], tuple(spec["hw"]), device)
    dtype = {"fp32": None, "bf16": torch.bfloat16, "fp16": torch.float16}[spec["dtype"]]
    scaler = torch.amp.GradScaler(device.type, enabled=dtype == torch.float16)

    def step() -> None:
        with torch.autocast(device.type, dtype=dtype or torch.float32, enabled=dtype is not None):
            src = model.encode(batch["src_rgb"], batch["src_K"], batch["src_c2w"])
            out = model.render_rays(src, batch["origins"], batch["dirs"], 1.0, 5.0, stratified=True)
            loss, _ = render_loss(out, batch["label"], batch["rgb"], cfg)
        opt.zero_grad(set_to_none=True)
        scaler.scale(loss).backward()
        scaler.step(opt)
        scaler.update()
        if not torch.isfinite(loss):
            raise FloatingPointError(f"sray.jobs.bench.model_cost: non-finite loss in {spec}.")

    times = _timed_runs(step, device, int(spec["steps"]) + 1)
    peak_gpu = int(torch.cuda.max_memory_allocated(device)) if device.type == "cuda" else 0
    rss = peak_rss_bytes()
    n_params = sum(p.numel() for p in model.parameters())
    rest = sorted(times[1:])
    return {"first": times[0], "seconds": rest[len(rest) // 2], "rss_bytes": rss,
            "gpu_peak_bytes": peak_gpu, "params": n_params}
