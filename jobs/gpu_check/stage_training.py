"""Stage ``training``: Accelerate training steps on one device in each low precision (fp16 with loss
scaling on CUDA) through the shared ``TrainStep``: steps/s, rays/s, peak memory, no non-finite step."""

from __future__ import annotations

import resource
import time

import torch

from sray.model.config import SRayConfig
from sray.model.ray_batch import RayBatchLoss
from sray.platform.common.model_input import ray_batch
from sray.platform.train.step import TrainStep, fused_adam

from .context import CheckContext, has_module
from .report import StageResult
from .synthetic import training_sample


def peak_mb(device: torch.device) -> float:
    """Peak memory in MiB: the CUDA allocator's peak since its last reset, else this process's peak resident set."""
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated(device) / 2**20
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def prepared_training(ctx: CheckContext, cfg: SRayConfig, precision: str, lr: float, grad_clip: float,
                      steps: int) -> tuple[torch.nn.Module, TrainStep, torch.device]:
    """A seeded ``RayBatchLoss`` of ``cfg`` and its fused Adam through Accelerate on ``ctx.device``, with the
    ``TrainStep`` of ``precision`` that training uses (up to ``steps`` non-finite steps in a row tolerated)."""
    from accelerate import Accelerator

    accelerator = Accelerator(mixed_precision="no", cpu=ctx.device.type != "cuda")
    torch.manual_seed(0)
    model = RayBatchLoss(cfg)
    model, optimizer = accelerator.prepare(model, fused_adam(list(model.parameters()), lr))
    step = TrainStep(list(model.parameters()), optimizer, grad_clip, precision, accelerator.device, steps)
    return model, step, accelerator.device


def timed_steps(ctx: CheckContext, precision: str, steps: int, rays: int | None = None) -> dict[str, float]:
    """Run ``steps`` training steps of ``rays`` rays (default ``ctx.rays``) after one warm-up; returns steps/s, rays/s,
    peak MiB and skipped steps."""
    rays = rays or ctx.rays
    cfg = SRayConfig(n_coarse=ctx.samples[0], n_fine=ctx.samples[1], n_source=ctx.views)
    model, step, device = prepared_training(ctx, cfg, precision, 1e-4, 1.0, steps + 1)
    sample = training_sample(ctx.views, ctx.image_hw, rays, 20, device)
    batch = ray_batch(sample)
    if ctx.device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(ctx.device)

    def one() -> None:
        with step.autocast():
            loss, _ = model(batch, sample.target_label, sample.target_rgb)
        step(loss)

    one()  # warm-up
    if ctx.device.type == "cuda":
        torch.cuda.synchronize(ctx.device)
    start = time.perf_counter()
    for _ in range(steps):
        one()
    if ctx.device.type == "cuda":
        torch.cuda.synchronize(ctx.device)
    seconds = time.perf_counter() - start
    return {"steps_per_s": steps / seconds, "rays_per_s": steps * rays / seconds,
            "peak_mb": peak_mb(ctx.device), "skipped": float(step.skipped_total)}


LARGE_BATCH = 4
"""The larger batch of this stage and of the ``recipe`` stage, in multiples of ``ctx.rays``: on one H100 or H200 a
1,024-ray step leaves the GPU partly idle (bf16 slower than fp32 there), 4,096 rays give 1.7-2.4 times the bf16
rays/s (docs/benchmarks.md, "GPU check")."""


def run(ctx: CheckContext) -> StageResult:
    """fp32 and each low precision at ``ctx.rays``, then the first low precision (bf16) at ``LARGE_BATCH`` times the
    rays; fails on a skipped (non-finite) step."""
    if not has_module("accelerate"):
        return StageResult("skipped", "accelerate is not installed here")
    steps = 2 if ctx.dry_run else 20
    rows, bad = [], []
    runs = [(p, ctx.rays) for p in ["no", *ctx.low_precisions()]] + [(ctx.low_precisions()[0], LARGE_BATCH * ctx.rays)]
    for precision, rays in runs:
        m = timed_steps(ctx, precision, steps, rays)
        label = "fp32" if precision == "no" else precision
        rows.append([label, str(rays), f"{m['steps_per_s']:.2f}", f"{m['rays_per_s']:.0f}", f"{m['peak_mb']:.0f}",
                     f"{m['skipped']:.0f}"])
        if m["skipped"]:
            bad.append(f"{label} at {rays} rays")
    hw = f"{ctx.image_hw[1]}x{ctx.image_hw[0]}"
    summary = (f"{ctx.samples[0]}+{ctx.samples[1]} samples, {ctx.views} views, {hw}: "
               + ", ".join(f"{r[0]} {r[3]} rays/s at {r[1]} rays" for r in rows))
    if bad:
        summary = f"non-finite steps in {', '.join(bad)}; " + summary
    return StageResult("failed" if bad else "passed", summary,
                       header=["precision", "rays per step", "steps/s", "rays/s", "peak MiB", "skipped steps"],
                       rows=rows)
