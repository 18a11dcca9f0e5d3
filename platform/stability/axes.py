"""The axes ``sray stability`` sweeps, each with levels that go from harmless to broken.

An axis is one of three kinds:

* ``perturb``: the source images or cameras are perturbed (:func:`perturb_views`, built on
  :mod:`sray.data_tools.perturbations`, whose units these levels use);
* ``sources``: the choice of source views changes (how many; or the query's nearest ranked
  neighbours are dropped, so more samples are seen by no source view);
* ``precision``: the autocast precision of inference (a categorical axis, fp32 first).

Which rows an axis stresses follows from the row (:meth:`Axis.applies`): every axis stresses every row, except
``unseen_rays`` (rows that render from source views) and ``precision`` (zero-shot rows: a pretrained model run
at another precision). A row that renders from no source view (Semantic-NeRF) has its training views perturbed on
``perturb`` axes, and on ``source_views`` the level is its number of training views; a row trained on the scene
that renders from sources is trained on the perturbed views and rendered from perturbed sources.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.data_tools.perturbations import exposure, gaussian_noise, jpeg, motion_blur, noisy_pose, occlude
from sray.platform.stability.rows import Row

POSE_CM_PER_DEG = 2.0
"""Pose-noise level L turns each camera by L degrees and moves it by ``POSE_CM_PER_DEG · L`` centimetres."""


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
    """Stresses only zero-shot rows."""

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
    """Perturb m views on a ``perturb`` axis: rgb (m, H, W, 3) uint8, c2w (m, 4, 4) -> new arrays.

    Each view draws its own perturbation from ``rng`` (in view order), so a (seed, level) pair always
    gives the same result; level 0 (or JPEG quality 100, or blur length 1) returns exact copies.
    """
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
