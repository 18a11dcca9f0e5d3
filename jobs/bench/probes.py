"""What ``sray bench model`` and ``sray bench profile`` run and how they measure it. Workloads: a training step and a
whole-image render on a synthetic scene (random sources seeing the query's frustum), sized by a spec dict: rays,
coarse, fine, views, hw, device, steps; optionally dtype, impl, fine_samples, piece, chunk (``Runtime`` fields; 0 or
absent: by device), compile and model (other ``SRayConfig`` fields). Measures: FLOPs with SDPA on its MATH backend
(the fused CPU kernel has no FLOP formula), the allocator's peak above its level before the call (the paper's "memory
increment"), training steps in a fresh process each (their peak RSS is theirs alone)."""

from __future__ import annotations

import dataclasses
import json
import os
import resource
import statistics
import tempfile
import time
from collections.abc import Callable
from contextlib import nullcontext

import torch
from torch.nn.attention import SDPBackend, sdpa_kernel
from torch.utils.flop_counter import FlopCounterMode

from sray.model.config import SRayConfig
from sray.model.cra import CrossReprojectionAttention
from sray.model.rays import pixel_rays
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel
from sray.platform.train.step import fused_adam


def resolve_device(device: str) -> torch.device:
    """``auto`` -> cuda when available, else cpu; anything else as given."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError("sray.jobs.bench.model_cost: device 'cuda' asked for but no CUDA device is visible; "
                         "use --device cpu or auto.")
    return dev


def attention_case(variant: str, rays: int, views: int, samples: int, channels: int,
                   device: torch.device) -> tuple[CrossReprojectionAttention, torch.Tensor, torch.Tensor]:
    """A seeded CRA module of ``variant`` and its input: space (R, m, N, C) and a validity mask (90% valid)."""
    gen = torch.Generator().manual_seed(0)
    torch.manual_seed(0)
    module = CrossReprojectionAttention(SRayConfig(feat_dim=channels, attention=variant, n_coarse=samples)).to(device)
    space = torch.randn(rays, views, samples, channels, generator=gen).to(device)
    valid = (torch.rand(rays, views, samples, generator=gen) < 0.9).to(device)
    return module, space, valid


def attention_call(module: CrossReprojectionAttention, space: torch.Tensor, valid: torch.Tensor,
                   backward: bool) -> Callable[[], None]:
    """A closure running the attention stage forward (and backward of its output sum)."""
    rays, samples = space.shape[0], space.shape[2]
    depth01 = ((torch.arange(samples, dtype=torch.float32) + 0.5) / samples).expand(rays, samples).to(space.device)

    def run() -> None:
        x = space.detach().requires_grad_(backward)
        with torch.set_grad_enabled(backward):
            out = module(x, valid, depth01)
            if backward:
                out.float().sum().backward()
    return run


def attention_flops(variant: str, sizes: dict, count_rays: int, device: torch.device, backward: bool) -> int:
    """Matmul FLOPs of the attention stage at ``sizes["rays"]`` rays (sizes: rays, views, samples, channels), counted
    at ``count_rays`` and scaled: exact, as every op is batched over rays (checked by counting at half as many)."""
    counts = []
    for r in (count_rays // 2, count_rays):
        module, space, valid = attention_case(variant, r, sizes["views"], sizes["samples"], sizes["channels"], device)
        with sdpa_kernel(SDPBackend.MATH), FlopCounterMode(display=False) as counter:
            attention_call(module, space, valid, backward)()
        counts.append(int(counter.get_total_flops()))
    if counts[1] != 2 * counts[0]:
        raise RuntimeError(f"sray.jobs.bench.probes: FLOPs of {variant} are not linear in rays ({counts}).")
    return counts[1] * sizes["rays"] // count_rays


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
        with open(trace) as f:
            events = [e["args"] for e in json.load(f)["traceEvents"]
                      if e.get("name") == "[memory]" and e["args"].get("Device Type") == 0]
    if not events:
        return 0
    start = events[0]["Total Allocated"] - events[0]["Bytes"]
    return max(int(e["Total Allocated"]) for e in events) - int(start)


def timed_runs(fn: Callable[[], None], device: torch.device, runs: int) -> list[float]:
    """Wall-clock seconds of ``runs`` consecutive calls of ``fn`` (CUDA synchronised)."""
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
    return statistics.median_high(timed_runs(fn, device, repeats + 1)[1:])


def peak_rss_bytes() -> int:
    """Peak resident set size of this process: VmHWM from /proc (Linux; ``ru_maxrss`` survives ``exec``, so a spawned
    child would report at least its parent's RSS at the fork), else ``ru_maxrss``."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024  # kB
    except OSError:
        pass
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024  # KiB on Linux


def synthetic_batch(rays: int, views: int, hw: tuple[int, int], device: torch.device, depth: bool = False) -> dict:
    """Random sources (m, 3, H, W), cameras, query rays, labels, colours; ``depth``: (m, H, W) in [1.5, 4.5] m."""
    h, w = hw
    gen = torch.Generator().manual_seed(0)
    K = torch.tensor([[w / 2, 0.0, (w - 1) / 2], [0.0, w / 2, (h - 1) / 2], [0.0, 0.0, 1.0]])
    c2w = torch.eye(4).repeat(views, 1, 1)
    c2w[:, 0, 3] = torch.linspace(-0.3, 0.3, views)
    c2w[:, 1, 3] = 0.1 * torch.sin(torch.arange(views, dtype=torch.float32))
    uv = torch.rand(rays, 2, generator=gen) * torch.tensor([w - 1.0, h - 1.0])
    origins, dirs = pixel_rays(K, torch.eye(4), uv)
    batch = {"src_rgb": torch.rand(views, 3, h, w, generator=gen), "src_K": K.expand(views, 3, 3).clone(),
             "src_c2w": c2w, "origins": origins, "dirs": dirs, "K": K,
             "label": torch.randint(0, 20, (rays,), generator=gen), "rgb": torch.rand(rays, 3, generator=gen)}
    if depth:
        batch["src_depth"] = 1.5 + 3.0 * torch.rand(views, h, w, generator=gen)
    return {k: v.to(device) for k, v in batch.items()}


def model_config(spec: dict) -> SRayConfig:
    """The spec's ``SRayConfig``: its ``model`` fields, sizes and fine_samples over the paper defaults."""
    cfg = SRayConfig(**spec.get("model", {}))
    return dataclasses.replace(cfg, n_coarse=spec["coarse"], n_fine=spec["fine"], n_source=spec["views"],
                               fine_samples=spec.get("fine_samples", cfg.fine_samples))


def spec_runtime(spec: dict) -> Runtime:
    """The spec's ``Runtime``: its impl, piece and chunk (defaults where it leaves them out or sets 0)."""
    fields = {"impl": "impl", "piece": "train_piece", "chunk": "chunk"}
    return Runtime(**{field: spec[key] for key, field in fields.items() if spec.get(key)})


def make_train_step(spec: dict) -> Callable[[], None]:
    """A closure running one full training step (encode, render, loss, backward, Adam) of ``spec``."""
    device = torch.device(spec["device"])
    torch.manual_seed(0)
    cfg, runtime = model_config(spec), spec_runtime(spec)
    model = SRayModel(cfg).to(device)
    if spec.get("compile"):
        model.coarse.compile()
        model.fine.compile()
    opt = fused_adam(list(model.parameters()), 1e-3)  # the optimizer training uses
    batch = synthetic_batch(spec["rays"], spec["views"], tuple(spec["hw"]), device, depth=cfg.inputs == "rgbd")
    dtype = {"fp32": None, "bf16": torch.bfloat16, "fp16": torch.float16}[spec.get("dtype", "fp32")]
    scaler = torch.amp.GradScaler(device.type, enabled=dtype == torch.float16)

    def step() -> None:
        with torch.autocast(device.type, dtype=dtype or torch.float32, enabled=dtype is not None):
            src = model.encode(batch["src_rgb"], batch["src_K"], batch["src_c2w"], batch.get("src_depth"))
            loss, _ = model.training_loss(src, batch["origins"], batch["dirs"], 1.0, 5.0, batch["label"], batch["rgb"],
                                          runtime)
        opt.zero_grad(set_to_none=True)
        scaler.scale(loss).backward()
        scaler.step(opt)
        scaler.update()
        if not torch.isfinite(loss):
            raise FloatingPointError(f"sray.jobs.bench.probes: non-finite loss in {spec}.")

    step.n_params = sum(p.numel() for p in model.parameters())  # type: ignore[attr-defined]
    return step


def render_case(spec: dict) -> Callable[[], None]:
    """A closure rendering one whole (H, W) view of the synthetic scene with ``render_image`` (no grad)."""
    device = torch.device(spec["device"])
    torch.manual_seed(0)
    model, runtime = SRayModel(model_config(spec)).to(device).eval(), spec_runtime(spec)
    h, w = spec["hw"]
    batch = synthetic_batch(1, spec["views"], (h, w), device)
    with torch.no_grad():
        src = model.encode(batch["src_rgb"], batch["src_K"], batch["src_c2w"])
    query = torch.eye(4, device=device)

    def render() -> None:
        model.render_image(src, batch["K"], query, (h, w), 1.0, 5.0, runtime)
    return render


def train_step_worker(spec: dict) -> dict:
    """Time ``spec["steps"]`` training steps after a warm-up one (meant for a fresh process; ``alloc='thp'`` needs
    THP_MEM_ALLOC_ENABLE=1 set before it starts): the first step's seconds (compilation included), the median of the
    others, the process's peak RSS, the GPU allocator's peak and the parameter count."""
    device = torch.device(spec["device"])
    step = make_train_step(spec)
    times = timed_runs(step, device, int(spec["steps"]) + 1)
    peak_gpu = int(torch.cuda.max_memory_allocated(device)) if device.type == "cuda" else 0
    return {"first": times[0], "seconds": statistics.median_high(times[1:]), "rss_bytes": peak_rss_bytes(),
            "gpu_peak_bytes": peak_gpu, "params": step.n_params}  # type: ignore[attr-defined]
