"""The axes ``sray stability`` sweeps, from harmless to broken (docs/stability.md, "Axes and their units"), and
what a point shows a row: many points show a row the same thing (every clean level is the clean input), so a point
becomes a :class:`PointSpec` and results are stored and reused per spec.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.data_tools.perturbations import exposure, gaussian_noise, jpeg, motion_blur, noisy_pose, occlude
from sray.platform.stability.presets import Preset
from sray.platform.stability.rows import Row

POSE_CM_PER_DEG = 2.0
"""Pose-noise level L turns each camera by L degrees and moves it by ``POSE_CM_PER_DEG · L`` centimetres."""
CLEAN_LEVELS = {"jpeg": 100, "blur": 1}
"""Harmless level of the perturbation axes whose harmless level is not 0."""


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
        elif axis == "image_noise":
            rgb_out[i] = gaussian_noise(rgb[i], level, rng)
        elif axis == "blur":
            rgb_out[i] = motion_blur(rgb[i], int(level), rng)
        elif axis == "exposure":
            rgb_out[i] = exposure(rgb[i], -level)
        elif axis == "jpeg":
            rgb_out[i] = jpeg(rgb[i], int(level))
        elif axis == "occlusion":
            rgb_out[i] = occlude(rgb[i], level, rng)[0]
    return rgb_out, c2w_out


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
