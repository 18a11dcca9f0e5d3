"""Stored study results as the publisher reads them: ``jobs/studies/results/<study>/<arm>--s<seed>.json`` (format 1,
one trial per file; docs/benchmarks.md names the format) and the statistics the published figures show."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

RESULTS = Path("jobs/studies/results")
"""The stored results' folder, relative to the repository."""


class ResultError(ValueError):
    """A stored result is absent or lacks a figure (the message names the file and field)."""


def trials(repo: Path, study: str, arm: str) -> list[dict[str, Any]]:
    """The stored trials of ``study``'s ``arm``, by seed; ResultError when there is none."""
    folder = Path(repo) / RESULTS / study
    found = sorted(folder.glob(f"{arm}--s*.json"), key=lambda p: int(p.stem.rsplit("--s", 1)[1]))
    if not found:
        raise ResultError(f"{folder}: no stored trial of arm {arm!r} ({arm}--s<seed>.json); run the study or import it")
    out = []
    for path in found:
        trial = json.loads(path.read_text())
        if trial.get("format") != 1 or trial.get("arm") != arm or trial.get("study") != study:
            raise ResultError(f"{path}: format/study/arm fields are {trial.get('format')}/{trial.get('study')}/"
                              f"{trial.get('arm')}; expected 1/{study}/{arm}")
        out.append(trial | {"_path": path})
    return out


def figure(trial: dict[str, Any], dotted: str) -> float | None:
    """The value at ``dotted`` (``metrics.zero_shot.miou``) of a trial: a number, or None when stored as null;
    ResultError naming the file and field when the field is absent."""
    value: Any = trial
    for key in dotted.split("."):
        if not isinstance(value, dict) or key not in value:
            raise ResultError(f"{trial['_path']}: no field {dotted}; re-import the trial with it (null if unknown)")
        value = value[key]
    return value


def present(trials_: list[dict[str, Any]], dotted: str) -> list[float]:
    """The non-null values of ``dotted`` over ``trials_``."""
    return [v for v in (figure(t, dotted) for t in trials_) if v is not None]


def mean_sd(values: list[float]) -> tuple[float, float | None]:
    """Mean and sample standard deviation (None for a single value)."""
    if not values:
        raise ValueError("mean_sd of no values")
    mean = sum(values) / len(values)
    if len(values) < 2:
        return mean, None
    return mean, math.sqrt(sum((v - mean) ** 2 for v in values) / (len(values) - 1))


def spread(values: list[float], digits: int = 2) -> str:
    """``mean ± sd`` with ``digits`` decimals (the mean alone for one value)."""
    mean, sd = mean_sd(values)
    return f"{mean:.{digits}f}" if sd is None else f"{mean:.{digits}f} ± {sd:.{digits}f}"


def seeds(trials_: list[dict[str, Any]]) -> str:
    """The trials' seeds as ``seed 0`` or ``seeds 0-2`` / ``seeds 0, 2``."""
    numbers = [t["seed"] for t in trials_]
    if len(numbers) == 1:
        return f"seed {numbers[0]}"
    if numbers == list(range(numbers[0], numbers[-1] + 1)):
        return f"seeds {numbers[0]}-{numbers[-1]}"
    return "seeds " + ", ".join(str(n) for n in numbers)
