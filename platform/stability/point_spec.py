"""What one point of the suite shows a method, and the key its result is stored under.

A point is an (axis, row, level, seed) (rows: :mod:`sray.platform.stability.rows`). Many points show a row the
same thing (every clean level is the same clean input; 8 source views on the ``source_views`` axis is the clean
point when the protocol uses 8), so a point is first turned into a :class:`PointSpec` and results are stored
and reused per spec: a spec is computed once whatever the axes that ask for it.
"""

from __future__ import annotations

from dataclasses import dataclass

from sray.platform.stability.axes import AXES
from sray.platform.stability.presets import Preset
from sray.platform.stability.rows import Row

CLEAN_LEVELS = {"jpeg": 100, "blur": 1}
"""Harmless level of the perturbation axes whose harmless level is not 0."""


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


def is_clean(axis: str, level: float) -> bool:
    """True when a perturbation axis's level changes nothing."""
    return level == CLEAN_LEVELS.get(axis, 0)


def point_spec(axis: str, row: Row, level: float | str, seed: int, preset: Preset) -> PointSpec:
    """The spec of (axis, row, level, seed) under ``preset``; ValueError when the axis does not stress the row.

    A trained row draws its training at random, so its points are always seeded; a zero-shot row's only when a
    perturbation is drawn."""
    if not AXES[axis].applies(row):
        raise ValueError(f"axis {axis!r} does not stress row {row.name!r} (sources: {row.uses_sources}, trained on "
                         f"the scene: {row.trained})")
    sources = row.uses_sources
    n_views, drop, pool, perturbation, precision = (preset.n_source if sources else 0), 0, "protocol", None, "fp32"
    kind = AXES[axis].kind
    if axis == "source_views":
        n_views = int(level)
    elif axis == "unseen_rays":
        n_views, drop, pool = preset.unseen_n_source, int(level), "all"
    elif kind == "precision":
        precision = str(level)
    elif not is_clean(axis, float(level)):
        perturbation = (axis, float(level))
    if not sources:
        pool = "pool"
    random = perturbation is not None or row.trained
    return PointSpec(row.name, n_views, drop, pool, perturbation, precision, seed if random else None)
