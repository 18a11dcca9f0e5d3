"""Stage ``recipe``: the hour recipe's model and losses (``synth-cpu-hour``: the source-view semantic head at
weight ``model.lambda_src_sem``, the 2D-only warm-up, then ray steps) at GPU size through the same Accelerate
``TrainStep`` as training: steps/s and rays/s of each phase and a short loss curve on one fixed batch.

The batch is synthetic but learnable: each source pixel's label is its colour's brightness band, so a working
2D warm-up must lower the source-view loss; a phase whose loss does not fall, or any skipped (non-finite)
step, fails the stage. The curve is written to ``<out>/recipe_curve.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import replace

import torch

from sray.platform.common.model_input import ray_batch
from sray.platform.config.recipes import synth_cpu_hour

from .context import CheckContext, has_module
from .report import StageResult
from .stage_training import LARGE_BATCH, peak_mb, prepared_training
from .synthetic import training_sample


def brightness_labels(rgb: torch.Tensor, n_classes: int) -> torch.Tensor:
    """int64 (m, H, W) labels of float (m, 3, H, W) colours in [0, 1]: the mean channel cut into n_classes bands."""
    return (rgb.mean(1) * n_classes).long().clamp(0, n_classes - 1)


def phase_curve(ctx: CheckContext, precision: str, steps: tuple[int, int], rays: int) -> list[dict[str, float]]:
    """Train the recipe's model for ``steps`` = (2D warm-up steps, ray steps) on one batch of ``rays`` query rays;
    per step: phase (0 = warm-up, 1 = ray), seconds (synchronised), loss, ``sem_src`` and the skipped-step count
    so far."""
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
        if ctx.device.type == "cuda":
            torch.cuda.synchronize(ctx.device)
        start = time.perf_counter()
        with step.autocast():
            loss, terms = model(batch, sample.target_label, sample.target_rgb, render=render)
        step(loss)
        if ctx.device.type == "cuda":
            torch.cuda.synchronize(ctx.device)
        curve.append({"phase": float(render), "seconds": time.perf_counter() - start, "loss": float(loss.detach()),
                      "sem_src": float(terms["sem_src"]), "skipped": float(step.skipped_total)})
    return curve


def _phase_cells(points: list[dict[str, float]], rays: int, renders: bool) -> list[str]:
    """steps/s and rays/s (median step after the phase's first, which holds allocation and kernel choice) and the
    loss and ``sem_src`` from the phase's first to its last step."""
    timed = points[1:] or points
    per_step = sorted(p["seconds"] for p in timed)[len(timed) // 2]
    return [f"{1 / per_step:.2f}", f"{rays / per_step:.0f}" if renders else "-",
            f"{points[0]['loss']:.3f} -> {points[-1]['loss']:.3f}",
            f"{points[0]['sem_src']:.3f} -> {points[-1]['sem_src']:.3f}"]


def run(ctx: CheckContext) -> StageResult:
    """fp32 and bf16 at ``ctx.rays``, then bf16 at ``LARGE_BATCH`` times the rays (the size that fills a GPU): the
    warm-up phase and the ray phase of the recipe, each a row; fails on a non-finite step or a source-view loss
    that does not fall over the warm-up."""
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
