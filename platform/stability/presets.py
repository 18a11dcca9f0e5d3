"""The sizes of ``sray stability --preset toy|cpu-small|gpu`` (docs/stability.md, "Presets"): levels per axis,
seeds, the world and pretraining used when no checkpoint is given, the evaluation budgets and the one CPU-second
budget of the trained rows.
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
    segmenter_cpu_seconds: float
    """CPU seconds of the 2D segmenter's training (``sray bench segmenter``) on the train scenes."""


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
    """Source views of the ``unseen_rays`` axis (from the whole source pool, past the dropped neighbours)."""
    eval_stride: int
    """Every ``eval_stride``-th pixel of each held-out view in each direction is rendered and scored."""
    chunk: int
    trained_scenes: int
    """Trained rows are trained and scored on the first this many test scenes; zero-shot rows on every one."""
    scene_cpu_seconds: float
    """The training budget of every trained row, per point and scene, the same for every method: CPU seconds of its
    training steps (``finetune.max_cpu_seconds``), so methods compare at equal compute whatever the machine's load."""
    scene_rays: int | None
    """Rays per training step of the trained rows (``finetune.rays_per_batch``); None: the checkpoint's."""
    nerf: SemanticNeRFSettings
    """Semantic-NeRF's network and learning rate."""


PRESETS: dict[str, Preset] = {p.name: p for p in (
    Preset("toy", {"source_views": (3, 1), "unseen_rays": (0, 3), "pose_noise": (0, 5), "image_noise": (0, 30),
                   "blur": (1, 7), "exposure": (0, 2), "jpeg": (100, 10), "occlusion": (0.0, 0.5),
                   "precision": ("fp32", "bf16")}, seeds=3,
           world=PresetWorld(World(1, 1, 20, 32, 40), pretrain_steps=6, rays=64,
                       n_coarse=6, n_fine=6, train_n_source=3, workers=1, segmenter_cpu_seconds=1.0),
           n_source=3, unseen_n_source=2, eval_stride=4, chunk=4096, trained_scenes=1, scene_cpu_seconds=0.1,
           scene_rays=64,
           nerf=SemanticNeRFSettings(depth=2, width=32, skip_layer=1, pos_freqs=4, dir_freqs=2, lr=5e-3)),
    Preset("cpu-small", {"source_views": (8, 4, 2, 1), "unseen_rays": (0, 4, 8, 12),
                         "pose_noise": (0, 2, 5, 10), "image_noise": (0, 10, 25, 50), "blur": (1, 5, 11, 21),
                         "exposure": (0, 1, 2, 3), "jpeg": (100, 30, 10, 5), "occlusion": (0.0, 0.25, 0.5, 0.75),
                         "precision": ("fp32", "bf16")}, seeds=3,
           world=PresetWorld(World(4, 2, 40, 120, 160), pretrain_steps=300, rays=256,
                       n_coarse=24, n_fine=24, train_n_source=4, workers=2, segmenter_cpu_seconds=600.0),
           n_source=8, unseen_n_source=4, eval_stride=8, chunk=4096, trained_scenes=1, scene_cpu_seconds=60.0,
           scene_rays=512,
           nerf=SemanticNeRFSettings(depth=4, width=128, skip_layer=2, pos_freqs=10, dir_freqs=4, lr=2e-3)),
    Preset("gpu", {"source_views": (16, 8, 4, 2, 1), "unseen_rays": (0, 2, 4, 8, 12),
                   "pose_noise": (0, 0.5, 1, 2, 5, 10), "image_noise": (0, 5, 10, 20, 40, 80),
                   "blur": (1, 3, 7, 15, 31), "exposure": (0, 1, 2, 3, 4), "jpeg": (100, 50, 20, 10, 5),
                   "occlusion": (0.0, 0.1, 0.25, 0.5, 0.75), "precision": ("fp32", "bf16", "fp16")}, seeds=5,
           world=PresetWorld(World(12, 4, 100, 240, 320), pretrain_steps=20_000, rays=1024, n_coarse=64,
                       n_fine=64, train_n_source=8, workers=1, segmenter_cpu_seconds=3600.0),
           n_source=8, unseen_n_source=8, eval_stride=1, chunk=8192, trained_scenes=4, scene_cpu_seconds=600.0,
           scene_rays=1024, nerf=SemanticNeRFSettings()),
)}
"""The suite sizes of ``sray stability --preset``."""
