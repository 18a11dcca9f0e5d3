"""The sizes of ``sray stability --preset toy|cpu-small|gpu``: levels per axis, seeds, the procedural
world and pretraining a preset builds when no data and checkpoints are given, and the budgets of its
evaluations.

Points whose inputs draw nothing at random (the clean point, fewer or farther source views, another
precision) are deterministic: they are computed once per method and reported with one "seed". Every
point that draws a perturbation is a mean over ``seeds`` perturbation seeds. Each preset pretrains
each S-Ray variant once (one pretraining seed); its tables say so.
"""

from __future__ import annotations

from dataclasses import dataclass

from sray.data_tools.synth.world import World
from sray.platform.config.fleet_config import SemanticNeRFSettings


@dataclass(frozen=True)
class PresetWorld:
    """The procedural scenes a preset generates and how it pretrains S-Ray on them."""

    scenes: World
    """The procedural world (world seed 0)."""
    pretrain_steps: int
    rays: int
    """Rays per pretraining step."""
    n_coarse: int
    n_fine: int
    train_n_source: int
    """Source views per pretraining sample."""
    workers: int
    """Ray Train workers of each pretraining."""


@dataclass(frozen=True)
class Preset:
    """Levels per axis, seeds, world and evaluation budgets of one suite size."""

    name: str
    levels: dict[str, tuple]
    """Axis -> levels, harmless first (``precision``: names)."""
    seeds: int
    """Perturbation seeds averaged at every point that draws one (at least 3)."""
    world: PresetWorld
    n_source: int
    """Fixed source views of the clean point and of every perturbation axis (the paper's protocol: 8)."""
    unseen_n_source: int
    """Source views of the ``unseen_rays`` axis, picked from the whole source pool after dropping the
    query's nearest ranked neighbours."""
    eval_stride: int
    """Every ``eval_stride``-th pixel of each held-out view in each direction is rendered and scored."""
    chunk: int
    """Rays per forward pass of an evaluation."""
    nerf_scenes: int
    """Semantic-NeRF is trained on the first this many test scenes (a from-scratch training per point)."""
    nerf_steps: int
    """Semantic-NeRF's step budget per point (the fleet's ``finetune.max_steps`` rule)."""
    nerf_seconds: float
    """Semantic-NeRF's training-time budget per point (the fleet's ``finetune.max_seconds`` rule). The CPU
    presets budget steps and keep this only as a guard: on a shared machine a time budget would make the
    score depend on the load."""
    nerf_rays: int
    """Rays per Semantic-NeRF step."""
    nerf: SemanticNeRFSettings
    """Semantic-NeRF's network and learning rate."""


PRESETS: dict[str, Preset] = {p.name: p for p in (
    Preset("toy", {"source_views": (3, 1), "unseen_rays": (0, 3), "pose_noise": (0, 5), "image_noise": (0, 30),
                   "blur": (1, 7), "exposure": (0, 2), "jpeg": (100, 10), "occlusion": (0.0, 0.5),
                   "precision": ("fp32", "bf16")}, seeds=3,
           world=PresetWorld(World(1, 1, 20, 32, 40), pretrain_steps=6, rays=64,
                       n_coarse=6, n_fine=6, train_n_source=3, workers=1),
           n_source=3, unseen_n_source=2, eval_stride=4, chunk=4096, nerf_scenes=1, nerf_steps=4,
           nerf_seconds=5.0, nerf_rays=64,
           nerf=SemanticNeRFSettings(depth=2, width=32, skip_layer=1, pos_freqs=4, dir_freqs=2, lr=5e-3)),
    Preset("cpu-small", {"source_views": (8, 4, 2, 1), "unseen_rays": (0, 4, 8, 12),
                         "pose_noise": (0, 2, 5, 10), "image_noise": (0, 10, 25, 50), "blur": (1, 5, 11, 21),
                         "exposure": (0, 1, 2, 3), "jpeg": (100, 30, 10, 5), "occlusion": (0.0, 0.25, 0.5, 0.75),
                         "precision": ("fp32", "bf16")}, seeds=3,
           world=PresetWorld(World(4, 2, 40, 120, 160), pretrain_steps=300, rays=256,
                       n_coarse=24, n_fine=24, train_n_source=4, workers=2),
           n_source=8, unseen_n_source=4, eval_stride=8, chunk=4096, nerf_scenes=1, nerf_steps=150,
           nerf_seconds=600.0, nerf_rays=512,
           nerf=SemanticNeRFSettings(depth=4, width=128, skip_layer=2, pos_freqs=10, dir_freqs=4, lr=2e-3)),
    Preset("gpu", {"source_views": (16, 8, 4, 2, 1), "unseen_rays": (0, 2, 4, 8, 12),
                   "pose_noise": (0, 0.5, 1, 2, 5, 10), "image_noise": (0, 5, 10, 20, 40, 80),
                   "blur": (1, 3, 7, 15, 31), "exposure": (0, 1, 2, 3, 4), "jpeg": (100, 50, 20, 10, 5),
                   "occlusion": (0.0, 0.1, 0.25, 0.5, 0.75), "precision": ("fp32", "bf16", "fp16")}, seeds=5,
           world=PresetWorld(World(12, 4, 100, 240, 320), pretrain_steps=20_000,
                       rays=1024, n_coarse=64, n_fine=64, train_n_source=8, workers=1),
           n_source=8, unseen_n_source=8, eval_stride=1, chunk=8192, nerf_scenes=4, nerf_steps=5000,
           nerf_seconds=300.0, nerf_rays=1024, nerf=SemanticNeRFSettings()),
)}
"""The suite sizes of ``sray stability --preset``."""
