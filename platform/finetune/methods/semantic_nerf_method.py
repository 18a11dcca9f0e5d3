"""Semantic-NeRF from scratch: the per-scene baseline, trained on the scene's rays; its artifact is the whole net."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from sray.platform.finetune.methods.method import ChartStyle, Method, SceneContext, SceneSetup

if TYPE_CHECKING:
    from torch import nn


def build(ctx: SceneContext) -> SceneSetup:
    """A seeded Semantic-NeRF of the scene (``nerf.*``) behind a ``NeRFLearner``; samples need no source view."""
    from sray.model.ray_chunks import render_chunk_rays
    from sray.platform.finetune.learners import NeRFLearner, build_semantic_nerf

    cfg, ft = ctx.cfg, ctx.cfg.finetune
    samples_per_ray = (cfg.nerf.n_coarse or ctx.train_cfg.model.n_coarse, cfg.nerf.n_fine or ctx.train_cfg.model.n_fine)
    net = build_semantic_nerf(ctx.shards, ctx.scene, ctx.n_classes, ctx.ignore_id, *samples_per_ray, cfg.nerf, ft.seed,
                              render_chunk_rays(ft.eval_chunk, ctx.device))
    learner = NeRFLearner(net, cfg.nerf.lr, ft.grad_clip, ft.precision, ctx.device, ft.max_nonfinite_in_row)
    return SceneSetup(learner=learner, n_source=1, top_k=1)  # only the query's rays are used


def load(artifact: Path, base_checkpoint: Path) -> nn.Module:
    """The scene's Semantic-NeRF rebuilt from its artifact (the shared checkpoint is not needed)."""
    from sray.platform.finetune.scene_artifacts import load_semantic_nerf

    return load_semantic_nerf(artifact)


METHOD = Method(
    name="semantic-nerf", summary="train Semantic-NeRF from scratch", build=build, load=load, uses_sources=False,
    artifact_file="semantic_nerf.safetensors", style=ChartStyle("Semantic-NeRF from scratch", "#d1495b", "s"))
