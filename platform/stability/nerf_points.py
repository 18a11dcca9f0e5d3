"""One point of the suite for Semantic-NeRF: a per-scene model trained from scratch on what the spec
shows it (all or some of the scene's source-pool views, perturbed or not), under the fleet's budget
rules (a step budget and a training-time budget, the first reached ends it), then scored on the
scene's held-out views from their true cameras.

Training uses the fleet's learner (:class:`~sray.platform.finetune.learners.NeRFLearner`: the shared
loss, optimiser step, clipping and non-finite guard); rays are drawn uniformly from random training
views, seeded by the spec's seed (which also seeds the network's initial weights).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import torch

from sray.data_tools.loader.samples import eval_sample, train_sample
from sray.platform.eval.scene_scoring import score_scene
from sray.platform.finetune.learners import NeRFLearner, semantic_nerf_for_views
from sray.platform.stability.point_spec import PointSpec
from sray.platform.stability.presets import Preset
from sray.platform.stability.sray_points import OutputWatch
from sray.platform.stability.stress_scenes import StressScene, perturbed_views


def training_views(pool: list[str], n: int) -> list[str]:
    """``n`` views spread evenly over the capture-ordered ``pool`` (0 or ``len(pool)`` or more: all of it)."""
    if n <= 0 or n >= len(pool):
        return list(pool)
    if n == 1:
        return [pool[len(pool) // 2]]
    return [pool[round(i * (len(pool) - 1) / (n - 1))] for i in range(n)]


def nerf_point(scene: StressScene, spec: PointSpec, preset: Preset, n_classes: int, ignore_id: int,
               device: torch.device, poison: bool = False) -> dict[str, Any]:
    """Train and score a Semantic-NeRF of ``scene`` at ``spec``: mIoU, PSNR, steps and seconds used."""
    seed = 0 if spec.seed is None else spec.seed
    train_ids = training_views(scene.pool_ids, spec.n_views)
    views = scene.views if spec.perturbation is None else perturbed_views(scene, train_ids, *spec.perturbation, seed)
    w = preset.world
    net = semantic_nerf_for_views(scene.meta, views, scene.image_size, n_classes, ignore_id, w.n_coarse, w.n_fine,
                                  preset.nerf, seed, preset.chunk)
    learner = NeRFLearner(net, preset.nerf.lr, grad_clip=1.0, precision="no", device=device, max_nonfinite_in_row=20)
    rng = np.random.default_rng(seed)
    steps, train_s = 0, 0.0
    while steps < preset.nerf_steps and train_s < preset.nerf_seconds:
        start = time.perf_counter()
        query = train_ids[int(rng.integers(len(train_ids)))]
        sample = train_sample(views, query, [query], preset.nerf_rays, rng, scene.name, scene.meta.near,
                              scene.meta.far, n_classes)
        loss, _ = learner.loss(sample)
        learner.step(loss)
        steps, train_s = steps + 1, train_s + time.perf_counter() - start
    watch = OutputWatch(poison)
    samples = [eval_sample(scene.views, q, [train_ids[0]], scene.name, scene.meta.near, scene.meta.far)
               for q in scene.test_ids]
    with learner.inference(), learner.step.autocast():
        scores = score_scene(lambda s: watch.wrap(learner.renderer(s)), samples, n_classes, ignore_id,
                             preset.eval_stride, preset.chunk, device).scores
    return {"miou": scores["miou"], "psnr": scores["psnr"], "nonfinite_rays": watch.nonfinite_rays,
            "steps": steps, "train_s": train_s, "train_views": len(train_ids),
            "scenes": {scene.name: {"miou": scores["miou"], "psnr": scores["psnr"]}}}
