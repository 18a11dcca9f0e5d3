"""Fleet results' ``curve`` (docs/CONTRACTS.md) as step functions (the model is the last evaluated until the next
evaluation or the end); averaging across scenes resamples every curve on the union of their points."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sray.platform.viz.chart_style import ChartedMethods

RESULT_FIELDS = ("scene", "method", "status", "curve")  # fields every result must have to be charted


def check_result(result: dict[str, Any], methods: ChartedMethods) -> None:
    """ValueError naming the result and the missing or unknown field."""
    missing = [f for f in RESULT_FIELDS if f not in result]
    who = f"fleet result {result.get('scene', '?')}/{result.get('method', '?')}"
    if missing:
        raise ValueError(f"{who}: fields {missing} are missing (see docs/CONTRACTS.md, 'Fleet results')")
    if result["method"] not in methods:
        raise ValueError(f"{who}: field 'method' is {result['method']!r}; use one of {tuple(methods)}")


def is_chartable(result: dict[str, Any]) -> bool:
    """A finished result with at least one evaluated point."""
    return result.get("status") == "finished" and bool(result.get("curve"))


def curve_xy(curve: list[dict[str, Any]], x_key: str, y_key: str) -> tuple[np.ndarray, np.ndarray]:
    """(x (n,), y (n,)) of a result's curve, stably sorted by x, without points missing a finite value."""
    pts = [(float(p[x_key]), float(p[y_key])) for p in curve
           if p.get(x_key) is not None and p.get(y_key) is not None
           and math.isfinite(float(p[x_key])) and math.isfinite(float(p[y_key]))]
    pts.sort(key=lambda p: p[0])
    if not pts:
        return np.zeros(0), np.zeros(0)
    x, y = zip(*pts)
    return np.asarray(x, float), np.asarray(y, float)


def step_hold(x: np.ndarray, y: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Values (len(grid),) at ``grid`` of the step function through (x, y) (x ascending): the y of the last point
    with x <= g (the last of several at one x), NaN before the first point."""
    idx = np.searchsorted(x, grid, side="right") - 1
    return np.where(idx >= 0, y[np.clip(idx, 0, None)], np.nan) if len(x) else np.full(len(grid), np.nan)


def average_curves(curves: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """(grid (k,), mean (k,)) of step-function curves on the union of their x values, from where every curve has
    started (none is extrapolated backwards; each holds its last value after its end); empty when none has a point."""
    curves = [(x, y) for x, y in curves if len(x)]
    if not curves:
        return np.zeros(0), np.zeros(0)
    grid = np.unique(np.concatenate([x for x, _ in curves]))
    grid = grid[grid >= max(float(x[0]) for x, _ in curves)]
    values = np.stack([step_hold(x, y, grid) for x, y in curves])  # (n_curves, k)
    return grid, values.mean(axis=0)


def zero_shot_value(result: dict[str, Any], y_key: str, methods: ChartedMethods) -> float | None:
    """The step-0 score of a result whose method starts from a zero-shot model (S-Ray), else None."""
    method = methods.get(result.get("method", ""))
    first = result["curve"][0] if result.get("curve") else None
    if method is None or method.zero_shot is None or first is None or int(first.get("step", -1)) != 0:
        return None
    value = first.get(y_key)
    return float(value) if value is not None and math.isfinite(float(value)) else None


def failure_note(results: list[dict[str, Any]]) -> str:
    """One line naming every result that is not charted (failed, or no evaluated point), or ''."""
    skipped = []
    for r in results:
        if is_chartable(r):
            continue
        why = r.get("error") or ("no evaluated point" if r.get("status") == "finished" else r.get("status") or "?")
        why = (str(why).splitlines() or ["?"])[0][:60]
        skipped.append(f"{r.get('scene', '?')}/{r.get('method', '?')} ({why})")
    return ("not plotted: " + "; ".join(skipped)) if skipped else ""
