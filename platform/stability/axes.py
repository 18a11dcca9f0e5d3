"""The axes ``sray stability`` sweeps, harmless to broken, and the presets (docs/stability.md, "Axes and their units",
"Presets"); a point becomes a :class:`PointSpec`, its result stored and reused per spec (clean levels coincide)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.data_tools.perturbations import exposure, gaussian_noise, jpeg, motion_blur, noisy_pose, occlude
from sray.data_tools.synth.world import World
from sray.platform.config.fleet_config import SemanticNeRFSettings
from sray.platform.stability.rows import Row

POSE_CM_PER_DEG = 2.0
"""Pose-noise level L turns each camera by L degrees and moves it by ``POSE_CM_PER_DEG · L`` centimetres."""
CLEAN_LEVELS = {"jpeg": 100, "blur": 1}
"""Harmless level of the perturbation axes whose harmless level is not 0."""
IMAGE_PERTURBATIONS = {"image_noise": lambda image, level, rng: gaussian_noise(image, level, rng),
                       "blur": lambda image, level, rng: motion_blur(image, int(level), rng),
                       "exposure": lambda image, level, rng: exposure(image, -level),
                       "jpeg": lambda image, level, rng: jpeg(image, int(level)),
                       "occlusion": lambda image, level, rng: occlude(image, level, rng)[0]}
"""Image axis -> the perturbation of one uint8 (H, W, 3) image at a level, drawing from a generator."""


@dataclass(frozen=True)
class Axis:
    """One stress axis: its kind, the unit of its levels and which rows it stresses."""

    name: str
    """Axis id (CLI ``--axes``, chart panel, MLflow child run)."""
    kind: str
    """``perturb``, ``sources`` or ``precision``."""
    unit: str
    """What a level means, for chart axes and tables."""
    sources_only: bool = False
    """Stresses only rows that render from source views."""
    zero_shot_only: bool = False

    def applies(self, row: Row) -> bool:
        """Whether this axis stresses ``row``."""
        return (row.uses_sources or not self.sources_only) and (not row.trained or not self.zero_shot_only)


AXES: dict[str, Axis] = {a.name: a for a in (
    Axis("source_views", "sources", "source views (per-scene models: training views)"),
    Axis("unseen_rays", "sources", "nearest ranked neighbours dropped (x: fraction of samples no source sees)",
         sources_only=True),
    Axis("pose_noise", "perturb", f"rotation in degrees (translation {POSE_CM_PER_DEG:g} cm per degree)"),
    Axis("image_noise", "perturb", "Gaussian noise sigma (8-bit levels)"),
    Axis("blur", "perturb", "motion-blur length (px)"),
    Axis("exposure", "perturb", "under-exposure (EV stops)"),
    Axis("jpeg", "perturb", "JPEG quality (100 = best)"),
    Axis("occlusion", "perturb", "fraction of each image occluded"),
    Axis("precision", "precision", "autocast precision", zero_shot_only=True),
)}
"""Every axis, in the order the suite runs and charts them."""


def perturb_views(axis: str, level: float, rgb: np.ndarray, c2w: np.ndarray,
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Perturb m views on a ``perturb`` axis: rgb (m, H, W, 3) uint8, c2w (m, 4, 4) -> new arrays. Each view draws
    from ``rng`` in view order; a harmless level returns exact copies."""
    if AXES[axis].kind != "perturb":
        raise ValueError(f"axis {axis!r} does not perturb views (its kind is {AXES[axis].kind!r})")
    rgb_out, c2w_out = rgb.copy(), np.array(c2w, dtype=np.float64, copy=True)
    if axis == "jpeg" and level >= 100 or axis != "jpeg" and level == 0:
        return rgb_out, c2w_out
    for i in range(len(rgb)):
        if axis == "pose_noise":
            c2w_out[i] = noisy_pose(c2w[i], level, POSE_CM_PER_DEG * level, rng)
        else:
            rgb_out[i] = IMAGE_PERTURBATIONS[axis](rgb[i], level, rng)
    return rgb_out, c2w_out


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


@dataclass(frozen=True)
class PointSpec:
    """The inputs of one row at one point (everything its score depends on)."""

    method: str
    """The row's name (``Row.name``)."""
    n_views: int
    """Rows with sources: source views per query; rows without: training views (0 = the whole source pool)."""
    drop: int
    """Rows with sources: nearest ranked neighbours skipped before the sources are taken (``unseen_rays``)."""
    pool: str
    """Rows with sources: where sources are ranked from, ``protocol`` (the ``source`` split; the whole source pool
    when more views are asked than it has) or ``all`` (``source`` + ``finetune``); ``pool`` for rows without."""
    perturbation: tuple[str, float] | None
    """(axis, level) of the perturbation applied to what the row sees, or None."""
    precision: str
    """Inference autocast precision (``fp32``, ``bf16``, ``fp16``)."""
    seed: int | None
    """Perturbation (and training) seed; None when nothing is drawn at random."""

    def key(self) -> str:
        """A file-name-safe id, equal for equal specs."""
        what = "clean" if self.perturbation is None else f"{self.perturbation[0]}-{self.perturbation[1]:g}"
        seed = "det" if self.seed is None else f"s{self.seed}"
        return f"{self.method}_{self.pool}-d{self.drop}-n{self.n_views}_{what}_{self.precision}_{seed}"


def point_spec(axis: str, row: Row, level: float | str, seed: int, preset: Preset) -> PointSpec:
    """The spec of (axis, row, level, seed) under ``preset``; ValueError when the axis does not stress the row. A
    trained row's points are always seeded (its training draws), a zero-shot row's only when perturbed."""
    if not AXES[axis].applies(row):
        raise ValueError(f"axis {axis!r} does not stress row {row.name!r} (sources: {row.uses_sources}, trained on "
                         f"the scene: {row.trained})")
    n_views = preset.n_source if row.uses_sources else 0
    drop, pool, perturbation, precision = 0, "protocol", None, "fp32"
    if axis == "source_views":
        n_views = int(level)
    elif axis == "unseen_rays":
        n_views, drop, pool = preset.unseen_n_source, int(level), "all"
    elif AXES[axis].kind == "precision":
        precision = str(level)
    elif float(level) != CLEAN_LEVELS.get(axis, 0):
        perturbation = (axis, float(level))
    if not row.uses_sources:
        pool = "pool"
    random = perturbation is not None or row.trained
    return PointSpec(row.name, n_views, drop, pool, perturbation, precision, seed if random else None)
