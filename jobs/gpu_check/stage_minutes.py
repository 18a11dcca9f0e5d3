"""Stage ``minutes``: the GPU-minutes recipe end to end (world, ``sray train``'s launcher, the hour's protocol:
zero-shot and held-out mIoU, 8 sources, whole images, fast s1 c0.9): minutes of each part, mIoU per training minute."""

from __future__ import annotations

import os
import time

from sray.data_tools.synth.world import World, make_world
from sray.model.fast_render import FastRender
from sray.platform.config.recipes import get_recipe

from .context import FULL_STACK, CheckContext, skipped_without
from .report import StageResult
from .synthetic import toy_world

RECIPE = "synth-gpu-minutes"
EVAL_FAST = FastRender(pixel_stride=1, confidence=0.9)
"""The hour recipe's evaluation render (``fast s1 c0.9``)."""
HOUR_WORLD = World(train_scenes=498, test_scenes=4, views=40, height=120, width=160, seed=0)
"""The hour recipe's world (``jobs/studies/hour-recipe.yaml``)."""
HELD_OUT_ROOMS = 8
"""Training rooms whose held-out views are scored (the studies' ``held_out_rooms``)."""


def run(ctx: CheckContext) -> StageResult:
    """Generate the world, train the recipe, score it; one row of minutes and mIoU."""
    if skipped := skipped_without(FULL_STACK, "the minutes stage needs the full stack"):
        return skipped
    from sray.platform.eval.zero_shot import evaluate_checkpoint, training_scenes
    from sray.platform.train.launcher import launch_training

    root = ctx.out / "minutes"
    start = time.perf_counter()
    world = toy_world(ctx.dry_run) if ctx.dry_run else HOUR_WORLD
    shards = make_world(world, root / "world", progress=False, workers=os.cpu_count() or 1)
    world_s = time.perf_counter() - start
    cfg = get_recipe(RECIPE)
    cfg.data.shards = str(shards)
    cfg.run.output_dir, cfg.run.tracking_uri = str(root / "jobs"), f"sqlite:///{root / 'mlflow.db'}"
    cfg.run.name, cfg.run.register_model = f"{RECIPE}-{time.strftime('%Y%m%d-%H%M%S')}", ""
    n_source = cfg.model.n_source
    if ctx.dry_run:
        cfg.model.n_source, (cfg.model.n_coarse, cfg.model.n_fine), n_source = ctx.views, ctx.samples, ctx.views
        cfg.data.rays_per_batch, cfg.data.loader_workers, cfg.data.top_k, cfg.data.val_scenes = ctx.rays, 0, 6, 1
        cfg.optim.steps, cfg.optim.warmup_2d_steps, cfg.optim.warmup_steps = 4, 2, 0
        cfg.run.gpus_per_worker, cfg.run.cpus_per_worker, cfg.run.precision = 0.0, 1.0, "no"
        cfg.run.val_every = cfg.run.ckpt_every = 4
    start = time.perf_counter()
    outcome = launch_training(cfg)
    train_s = time.perf_counter() - start
    if outcome.latest_checkpoint is None:
        return StageResult("failed", f"{RECIPE}: training wrote no checkpoint ({outcome.status})")
    start = time.perf_counter()
    scores = {}
    for name, scenes in (("zero-shot", None), ("held-out", training_scenes(shards, HELD_OUT_ROOMS))):
        report = evaluate_checkpoint(outcome.latest_checkpoint, shards, scenes, root / f"eval-{name}",
                                     n_source=n_source, stride=1, tracking_uri=cfg.run.tracking_uri,
                                     experiment=cfg.run.experiment, progress=False, fast=EVAL_FAST)
        scores[name] = 100 * report["mean"]["dataset_level"]["miou"]
    eval_s = time.perf_counter() - start
    minutes = train_s / 60
    row = [RECIPE, str(cfg.optim.steps), str(cfg.data.rays_per_batch), cfg.run.precision, f"{world_s / 60:.1f}",
           f"{minutes:.1f}", f"{eval_s / 60:.1f}", f"{scores['zero-shot']:.2f}", f"{scores['held-out']:.2f}",
           f"{scores['zero-shot'] / minutes:.2f}", f"{scores['held-out'] / minutes:.2f}"]
    summary = (f"{RECIPE}: {cfg.optim.steps} steps in {minutes:.1f} min (world {world_s / 60:.1f} min, eval "
               f"{eval_s / 60:.1f} min): zero-shot {scores['zero-shot']:.2f}%, held-out {scores['held-out']:.2f}% mIoU")
    return StageResult("passed", summary, rows=[row], header=[
        "recipe", "steps", "rays/step", "precision", "world min", "training min", "eval min", "zero-shot mIoU %",
        "held-out mIoU %", "zero-shot mIoU per training min", "held-out mIoU per training min"])
