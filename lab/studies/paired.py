"""Paired differences of a study: each arm minus the baseline arm, seed by seed, over the seeds both hold.

Two trials of the same seed share their data order and initialisation, so their difference cancels most of the
seed-to-seed spread; the mean and the sample standard deviation (n - 1) of those per-seed differences say how large
an arm's effect is and how much it moves between seeds. One shared seed gives a difference without a spread.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from typing import Any

from sray.lab.studies.results import metric


@dataclass(frozen=True)
class Paired:
    """One arm's paired difference to the baseline on one split."""

    arm: str
    split: str
    seeds: tuple[int, ...]
    """The seeds both arms hold a value for, ascending."""
    differences: tuple[float, ...]
    """Arm minus baseline, per seed of :attr:`seeds` (points of the metric)."""

    @property
    def mean(self) -> float | None:
        """The mean difference (None without a shared seed)."""
        return statistics.fmean(self.differences) if self.differences else None

    @property
    def std(self) -> float | None:
        """The sample standard deviation of the differences (None below two shared seeds)."""
        return statistics.stdev(self.differences) if len(self.differences) > 1 else None


def by_arm_and_seed(results: dict[str, dict[str, Any]], split: str, name: str = "miou") -> dict[str, dict[int, float]]:
    """arm -> seed -> the metric on ``split``, for the results that measured it."""
    table: dict[str, dict[int, float]] = {}
    for result in results.values():
        value = metric(result, split, name)
        if value is not None:
            table.setdefault(result["arm"], {})[int(result["seed"])] = value
    return table


def paired_differences(results: dict[str, dict[str, Any]], baseline: str, split: str,
                       name: str = "miou") -> list[Paired]:
    """Every arm but ``baseline`` (in the order the results list them) against it on ``split``."""
    table = by_arm_and_seed(results, split, name)
    base = table.get(baseline, {})
    arms = list(dict.fromkeys(r["arm"] for r in results.values() if r["arm"] != baseline))
    out = []
    for arm in arms:
        shared = tuple(sorted(set(table.get(arm, {})) & set(base)))
        out.append(Paired(arm, split, shared, tuple(table[arm][s] - base[s] for s in shared)))
    return out


def mean_and_std(values: list[float]) -> tuple[float | None, float | None]:
    """(mean, sample standard deviation) of ``values``; None where there are too few."""
    return (statistics.fmean(values) if values else None, statistics.stdev(values) if len(values) > 1 else None)
