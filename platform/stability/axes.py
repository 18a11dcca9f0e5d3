"""The axes ``sray stability`` sweeps, each with levels that go from harmless to broken.

An axis is one of three kinds:

* ``perturb``: the source images or cameras are perturbed (:func:`perturb_views`, built on
  :mod:`sray.data_tools.perturbations`, whose units these levels use);
* ``sources``: the choice of source views changes (how many; or the query's nearest ranked
  neighbours are dropped, so more samples are seen by no source view);
* ``precision``: the autocast precision of inference (a categorical axis, fp32 first).

Semantic-NeRF has no source views: on ``perturb`` axes its training views get the same perturbation,
and on ``source_views`` the level is its number of training views.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.data_tools.perturbations import exposure, gaussian_noise, jpeg, motion_blur, noisy_pose, occlude

POSE_CM_PER_DEG = 2.0
"""Pose-noise level L turns each camera by L degrees and moves it by ``POSE_CM_PER_DEG · L`` centimetres."""

SOURCE_METHODS = ("sray", "sray-no-cra")
"""Methods that read source views (S-Ray with full CRA, and S-Ray pretrained with ``attention=none``)."""
ALL_METHODS = (*SOURCE_METHODS, "semantic-nerf")
"""Every method the suite compares."""


@dataclass(frozen=True)
class Axis:
    """One stress axis: its kind, the unit of its levels and which methods it applies to."""

    name: str
    """Axis id (CLI ``--axes``, chart panel, MLflow child run)."""
    kind: str
    """``perturb``, ``sources`` or ``precision``."""
    unit: str
    """What a level means, for chart axes and tables."""
    methods: tuple[str, ...]
    """Methods this axis applies to."""


AXES: dict[str, Axis] = {a.name: a for a in (
    Axis("source_views", "sources", "source views (Semantic-NeRF: training views)", ALL_METHODS),
    Axis("unseen_rays", "sources", "nearest ranked neighbours dropped (x: fraction of samples no source sees)",
         SOURCE_METHODS),
    Axis("pose_noise", "perturb", f"rotation in degrees (translation {POSE_CM_PER_DEG:g} cm per degree)", ALL_METHODS),
    Axis("image_noise", "perturb", "Gaussian noise sigma (8-bit levels)", ALL_METHODS),
    Axis("blur", "perturb", "motion-blur length (px)", ALL_METHODS),
    Axis("exposure", "perturb", "under-exposure (EV stops)", ALL_METHODS),
    Axis("jpeg", "perturb", "JPEG quality (100 = best)", ALL_METHODS),
    Axis("occlusion", "perturb", "fraction of each image occluded", ALL_METHODS),
    Axis("precision", "precision", "autocast precision", SOURCE_METHODS),
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
