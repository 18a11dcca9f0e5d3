"""Stages ``training`` (the paper's model per precision: steps/s, rays/s, peak memory, no non-finite step) and
``recipe`` (the hour recipe's 2D warm-up then ray steps on one learnable batch: speed, ``<out>/recipe_curve.json``)."""

from __future__ import annotations

import json
import resource
import time
from dataclasses import replace

import torch

from sray.model.config import SRayConfig
from sray.model.ray_batch import RayBatchLoss
from sray.platform.common.model_input import ray_batch
from sray.platform.config.recipes import synth_cpu_hour
from sray.platform.train.step import TrainStep, fused_adam

from .context import CheckContext, has_module
from .report import StageResult
from .synthetic import training_sample

LARGE_BATCH = 4
"""The larger batch of both stages, in multiples of ``ctx.rays``: on one H100 or H200 a 1,024-ray step leaves the GPU
partly idle (bf16 slower than fp32 there), 4,096 rays keep it busy (the gpu-check reports in docs/benchmarks.md)."""


def peak_mb(device: torch.device) -> float:
    """Peak memory in MiB: the CUDA allocator's peak since its last reset, else this process's peak resident set."""
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated(device) / 2**20
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def prepared_training(ctx: CheckContext, cfg: SRayConfig, precision: str, lr: float, grad_clip: float,
                      steps: int) -> tuple[torch.nn.Module, TrainStep, torch.device]:
    """A seeded ``RayBatchLoss`` of ``cfg`` and its fused Adam through Accelerate on ``ctx.device``, with the
    ``TrainStep`` of ``precision`` (up to ``steps`` non-finite steps in a row tolerated)."""
    from accelerate import Accelerator

    accelerator = Accelerator(mixed_precision="no", cpu=ctx.device.type != "cuda")
    torch.manual_seed(0)
    model = RayBatchLoss(cfg)
    model, optimizer = accelerator.prepare(model, fused_adam(list(model.parameters()), lr))
    step = TrainStep(list(model.parameters()), optimizer, grad_clip, precision, accelerator.device, steps)
    return model, step, accelerator.device


def _synchronize(ctx: CheckContext) -> None:
    if ctx.device.type == "cuda":
        torch.cuda.synchronize(ctx.device)


def timed_steps(ctx: CheckContext, precision: str, steps: int, rays: int) -> dict[str, float]:
    """Run ``steps`` training steps of ``rays`` rays after one warm-up: steps/s, rays/s, peak MiB, skipped steps."""
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
    _synchronize(ctx)
    start = time.perf_counter()
    for _ in range(steps):
        one()
    _synchronize(ctx)
    seconds = time.perf_counter() - start
    return {"steps_per_s": steps / seconds, "rays_per_s": steps * rays / seconds,
            "peak_mb": peak_mb(ctx.device), "skipped": float(step.skipped_total)}


def run(ctx: CheckContext) -> StageResult:
    """Stage ``training``: fp32 and each low precision at ``ctx.rays``, then the first low precision at
    ``LARGE_BATCH`` times the rays; fails on a skipped (non-finite) step."""
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


def brightness_labels(rgb: torch.Tensor, n_classes: int) -> torch.Tensor:
    """int64 (m, H, W) labels of float (m, 3, H, W) colours in [0, 1]: the mean channel cut into n_classes bands."""
    return (rgb.mean(1) * n_classes).long().clamp(0, n_classes - 1)


def phase_curve(ctx: CheckContext, precision: str, steps: tuple[int, int], rays: int) -> list[dict[str, float]]:
    """Train the hour recipe's model for ``steps`` = (2D warm-up steps, ray steps) on one batch of ``rays`` query
    rays; per step: phase (0 = warm-up, 1 = ray), seconds, loss, ``sem_src`` and the skipped steps so far."""
    recipe = synth_cpu_hour()
    cfg = replace(recipe.model, n_coarse=ctx.samples[0], n_fine=ctx.samples[1], n_source=ctx.views)
    model, step, device = prepared_training(ctx, cfg, precision, recipe.optim.lr, recipe.optim.grad_clip,
                                            sum(steps) + 1)
    sample = training_sample(ctx.views, ctx.image_hw, rays, cfg.n_classes, device)
    sources = replace(sample.sources, label=brightness_labels(sample.sources.rgb, cfg.n_classes))
    batch = ray_batch(replace(sample, sources=sources))
    if ctx.device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(ctx.device)
    curve = []
    for i in range(sum(steps)):
        render = i >= steps[0]
        _synchronize(ctx)
        start = time.perf_counter()
        with step.autocast():
            loss, terms = model(batch, sample.target_label, sample.target_rgb, render=render)
        step(loss)
        _synchronize(ctx)
        curve.append({"phase": float(render), "seconds": time.perf_counter() - start, "loss": float(loss.detach()),
                      "sem_src": float(terms["sem_src"]), "skipped": float(step.skipped_total)})
    return curve


def _phase_cells(points: list[dict[str, float]], rays: int, renders: bool) -> list[str]:
    """steps/s, rays/s (median step after the first: allocation, kernel choice), loss and sem_src first -> last."""
    timed = points[1:] or points
    per_step = sorted(p["seconds"] for p in timed)[len(timed) // 2]
    return [f"{1 / per_step:.2f}", f"{rays / per_step:.0f}" if renders else "-",
            f"{points[0]['loss']:.3f} -> {points[-1]['loss']:.3f}",
            f"{points[0]['sem_src']:.3f} -> {points[-1]['sem_src']:.3f}"]


def recipe(ctx: CheckContext) -> StageResult:
    """Stage ``recipe``: fp32 and bf16 at ``ctx.rays``, then bf16 at ``LARGE_BATCH`` times the rays, a row per phase;
    fails on a non-finite step or a source-view loss that does not fall over the warm-up."""
    if not has_module("accelerate"):
        return StageResult("skipped", "accelerate is not installed here")
    steps = (3, 3) if ctx.dry_run else (20, 40)
    rows, bad, curves = [], [], {}
    for precision, rays in (("no", ctx.rays), ("bf16", ctx.rays), ("bf16", LARGE_BATCH * ctx.rays)):
        label = "fp32" if precision == "no" else precision
        curve = phase_curve(ctx, precision, steps, rays)
        curves[label if rays == ctx.rays else f"{label} at {rays} rays"] = curve
        warm, ray = curve[:steps[0]], curve[steps[0]:]
        peak = f"{peak_mb(ctx.device):.0f}"
        rows.append([f"{label} 2D warm-up", str(rays), *_phase_cells(warm, rays, False), peak])
        rows.append([f"{label} ray steps", str(rays), *_phase_cells(ray, rays, True), peak])
        if curve[-1]["skipped"]:
            bad.append(f"{label} at {rays} rays: {curve[-1]['skipped']:.0f} non-finite steps")
        if warm[-1]["sem_src"] >= warm[0]["sem_src"]:
            bad.append(f"{label} at {rays} rays: the source-view loss did not fall over the warm-up")
    (ctx.out / "recipe_curve.json").write_text(json.dumps({"steps": steps, "curves": curves}, indent=1) + "\n")
    hw = f"{ctx.image_hw[1]}x{ctx.image_hw[0]}"
    summary = (f"synth-cpu-hour model, {ctx.samples[0]}+{ctx.samples[1]} samples, {ctx.views} views, {hw}, "
               f"{steps[0]} warm-up + {steps[1]} ray steps: "
               + ", ".join(f"{r[0]} {r[3]} rays/s at {r[1]} rays" for r in rows if r[3] != "-"))
    if bad:
        summary = "; ".join(bad) + "; " + summary
    return StageResult("failed" if bad else "passed", summary,
                       header=["phase", "rays per step", "steps/s", "rays/s", "loss first -> last",
                               "sem_src first -> last", "peak MiB (both phases)"], rows=rows)
