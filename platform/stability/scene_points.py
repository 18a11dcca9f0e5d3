"""One point of a row trained on the scene: the method's fleet learner trained on what the spec shows of one test
scene for the suite's CPU-second budget, scored on its held-out views (docs/stability.md, "Trained on the scene")."""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from sray.data_tools.loader.samples import eval_sample, ranked_candidates, train_sample
from sray.data_tools.loader.views import StoredView
from sray.platform.config.fleet_config import FinetuneSettings, FleetConfig, TransferSettings
from sray.platform.config.held_out_render import HeldOutRender
from sray.platform.config.train_config import TrainConfig
from sray.platform.eval.view_scoring import score_scene
from sray.platform.finetune.methods.method import SceneContext, SceneSetup
from sray.platform.finetune.methods.registry import get_method
from sray.platform.finetune.step_budget import StepClock, time_limit_reached
from sray.platform.stability.axes import PointSpec, Preset
from sray.platform.stability.rows import Row
from sray.platform.stability.stress_scenes import (OutputWatch, StressScene, perturbed_views, source_samples,
                                                   unseen_fraction)
from sray.platform.train.step import step_seed


def scene_settings(preset: Preset, segmenter: Path | None) -> FleetConfig:
    """The fleet settings of every trained row: the preset's network, rays and ``scene_cpu_seconds``, full renders."""
    if preset.scene_cpu_seconds <= 0:
        raise ValueError(f"stability preset {preset.name!r}: scene_cpu_seconds is {preset.scene_cpu_seconds}; the rows "
                         "trained on the scene need a positive CPU budget")
    return FleetConfig(finetune=FinetuneSettings(max_cpu_seconds=preset.scene_cpu_seconds,
                                                 held_out=HeldOutRender(stride=2, render="full"),
                                                 rays_per_batch=preset.scene_rays),
                       nerf=preset.nerf, transfer=TransferSettings(segmenter=str(segmenter or "")))


@dataclass(frozen=True)
class SceneTraining:
    """What every trained-on-scene point of a process starts from (loaded once)."""

    base: nn.Module
    """The shared S-Ray checkpoint's model, on the CPU (each point trains a copy)."""
    train_cfg: TrainConfig
    """The checkpoint's training config (the defaults the methods inherit: rays, samples per ray, ``top_k``)."""
    base_sha256: str
    """sha256 of the checkpoint's ``state.pt``."""
    cfg: FleetConfig
    shards: Path
    stored_neighbours: int
    """Ranked neighbours the shards store per view."""
    n_classes: int
    ignore_id: int
    device: torch.device


def training_views(pool: list[str], n: int) -> list[str]:
    """``n`` views spread evenly over the capture-ordered ``pool`` (0 or ``len(pool)`` or more: all of it)."""
    if n <= 0 or n >= len(pool):
        return list(pool)
    if n == 1:
        return [pool[len(pool) // 2]]
    return [pool[round(i * (len(pool) - 1) / (n - 1))] for i in range(n)]


def scene_setup(training: SceneTraining, row: Row, scene: str, seed: int) -> SceneSetup:
    """The row's method built for ``scene`` by its registry record, on a copy of the shared model, seeded."""
    base = copy.deepcopy(training.base)
    cfg = dataclasses.replace(training.cfg, finetune=dataclasses.replace(training.cfg.finetune, seed=seed))
    return get_method(row.method).build(SceneContext(
        scene=scene, shards=training.shards, base=base, base_sha256=training.base_sha256, train_cfg=training.train_cfg,
        cfg=cfg, n_classes=training.n_classes, ignore_id=training.ignore_id,
        stored_neighbours=training.stored_neighbours, device=training.device))


def train_for_budget(setup: SceneSetup, training: SceneTraining, scene: StressScene, views: dict[str, StoredView],
                     train_ids: list[str], seed: int) -> tuple[int, StepClock]:
    """Train ``setup.learner`` on samples of ``train_ids`` until ``finetune.max_cpu_seconds`` (or a wall budget) is
    spent; (steps, the clock). A query with fewer neighbours than sources takes itself."""
    ft, learner = training.cfg.finetune, setup.learner
    rays = ft.rays_per_batch or training.train_cfg.data.rays_per_batch
    top_k, allowed = max(setup.top_k, setup.n_source), set(train_ids)
    rng = np.random.default_rng(seed)
    clock, steps = StepClock(), 0
    while time_limit_reached(ft, clock) is None:
        with clock.step():
            query = train_ids[int(rng.integers(len(train_ids)))]
            candidates = ranked_candidates(views[query], allowed, top_k)
            picked = rng.choice(len(candidates), min(setup.n_source, len(candidates)), replace=False)
            sources = ([candidates[int(i)] for i in picked] + [query] * setup.n_source)[:setup.n_source]
            torch.manual_seed(step_seed(seed, 0, steps))
            sample = train_sample(views, query, sources, rays, rng, scene.name, scene.meta.near, scene.meta.far,
                                  training.n_classes, None, setup.source_labels)
            loss, _ = learner.loss(sample)
            learner.step(loss)
        steps += 1
    return steps, clock


def scene_point(training: SceneTraining, row: Row, scene: StressScene, spec: PointSpec, stride: int, chunk: int,
                probe: tuple[int, float], poison: bool = False) -> dict[str, Any]:
    """Train ``row``'s method on ``scene`` at ``spec`` and score it: scores, non-finite rays, steps, CPU and wall
    seconds, training views and (rows with sources) the unseen fraction (``probe``: ``zero_shot_point``)."""
    seed = 0 if spec.seed is None else spec.seed
    train_ids = scene.pool_ids if row.uses_sources else training_views(scene.pool_ids, spec.n_views)
    views = scene.views if spec.perturbation is None else perturbed_views(scene, train_ids, *spec.perturbation, seed)
    setup = scene_setup(training, row, scene.name, seed)
    steps, clock = train_for_budget(setup, training, scene, views, train_ids, seed)
    samples = (source_samples(scene, views, spec) if row.uses_sources else
               [eval_sample(views, q, [train_ids[0]], scene.name, scene.meta.near, scene.meta.far)
                for q in scene.test_ids])
    learner, watch = setup.learner, OutputWatch(poison)
    with learner.inference(), learner.step.autocast():
        scores = score_scene(lambda s: watch.wrap(learner.renderer(s)), samples, training.n_classes,
                             training.ignore_id, stride, chunk, training.device, learner.fast).scores
    unseen = ({"unseen_fraction": sum(unseen_fraction(s, stride, *probe) for s in samples) / len(samples)}
              if row.uses_sources else {})
    return {"miou": scores["miou"], "psnr": scores["psnr"], "nonfinite_rays": watch.nonfinite_rays, "steps": steps,
            "cpu_s": clock.cpu_s, "train_s": clock.wall_s, "train_views": len(train_ids), **unseen,
            "scenes": {scene.name: {"miou": scores["miou"], "psnr": scores["psnr"]}}}
