"""What one point of the suite shows a method, and the key its result is stored under.

A point is an (axis, method, level, seed). Many points show a method the same thing (every clean
level is the same clean input; 8 source views on the ``source_views`` axis is the clean point when
the protocol uses 8), so a point is first turned into a :class:`PointSpec` and results are stored
and reused per spec: a spec is computed once whatever the axes that ask for it.
"""

from __future__ import annotations

from dataclasses import dataclass

from sray.platform.stability.axes import AXES, SOURCE_METHODS
from sray.platform.stability.presets import Preset

CLEAN_LEVELS = {"jpeg": 100, "blur": 1}
"""Harmless level of the perturbation axes whose harmless level is not 0."""


@dataclass(frozen=True)
class PointSpec:
    """The inputs of one method at one point (everything its score depends on)."""

    method: str
    n_views: int
    """S-Ray: source views per query; Semantic-NeRF: training views (0 = the whole source pool)."""
    drop: int
    """S-Ray: nearest ranked neighbours skipped before the sources are taken (``unseen_rays``)."""
    pool: str
    """S-Ray: where sources are ranked from, ``protocol`` (the ``source`` split; the whole source pool when
    more views are asked than it has) or ``all`` (``source`` + ``finetune``)."""
    perturbation: tuple[str, float] | None
    """(axis, level) of the perturbation applied to what the method sees, or None."""
    precision: str
    """Inference autocast precision (``fp32``, ``bf16``, ``fp16``)."""
    seed: int | None
    """Perturbation (and Semantic-NeRF training) seed; None when nothing is drawn at random."""

    def key(self) -> str:
        """A file-name-safe id, equal for equal specs."""
        what = "clean" if self.perturbation is None else f"{self.perturbation[0]}-{self.perturbation[1]:g}"
        seed = "det" if self.seed is None else f"s{self.seed}"
        return f"{self.method}_{self.pool}-d{self.drop}-n{self.n_views}_{what}_{self.precision}_{seed}"


def is_clean(axis: str, level: float) -> bool:
    """True when a perturbation axis's level changes nothing."""
    return level == CLEAN_LEVELS.get(axis, 0)


def point_spec(axis: str, method: str, level: float | str, seed: int, preset: Preset) -> PointSpec:
    """The spec of (axis, method, level, seed) under ``preset``; ValueError when the axis skips the method."""
    if method not in AXES[axis].methods:
        raise ValueError(f"axis {axis!r} does not apply to method {method!r} (it applies to {AXES[axis].methods})")
    sray = method in SOURCE_METHODS
    n_views, drop, pool, perturbation, precision = (preset.n_source if sray else 0), 0, "protocol", None, "fp32"
    kind = AXES[axis].kind
    if axis == "source_views":
        n_views = int(level)
    elif axis == "unseen_rays":
        n_views, drop, pool = preset.unseen_n_source, int(level), "all"
    elif kind == "precision":
        precision = str(level)
    elif not is_clean(axis, float(level)):
        perturbation = (axis, float(level))
    if not sray:
        pool = "pool"
    random = perturbation is not None or not sray
    return PointSpec(method, n_views, drop, pool, perturbation, precision, seed if random else None)
