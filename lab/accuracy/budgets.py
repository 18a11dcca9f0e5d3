"""The equal-budget table of ``sray lab accuracy``: each per-scene method's mean held-out mIoU at each wall-clock
budget of the fleet comparison (``accuracy_fleet``).

Its columns are the methods of the stored fleet results, in the method registry's order (results of a method not
registered are refused by name); each header names the method's chart label and the inputs its results' protocol
records (``RGB``, ``RGB-D``; results stored before fleets recorded a protocol say so). Budget 0 is the step-0
score: zero-shot for a method whose record has a zero-shot model, untrained otherwise.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from sray.platform.common.eval_protocol import results_inputs
from sray.platform.finetune.methods.registry import get_method, method_names
from sray.platform.viz.curves import step_hold

BUDGET_TABLE = "Per-scene methods at equal wall-clock budgets"
"""The table's title in the benchmark's section."""
FORMER_TITLES = ("S-Ray finetune vs Semantic-NeRF at equal wall-clock budgets",)
"""Titles the table was stored under before (replaced by it)."""
UNRECORDED = "inputs not recorded"
"""Header note of a method whose stored results carry no protocol."""


def at_budget(result: dict[str, Any], budget: float, key: str = "miou") -> float:
    """The held-out score a finetune had reached after ``budget`` seconds (last evaluation before it)."""
    curve = [c for c in result.get("curve", []) if c.get(key) is not None]
    x = np.array([c["wall_s"] for c in curve], dtype=float)
    y = np.array([c[key] for c in curve], dtype=float)
    return float(step_hold(x, y, np.array([budget]))[0])


def fleet_methods(results: list[dict[str, Any]]) -> list[str]:
    """The methods of ``results``, in registry order; ValueError names a method that is not registered."""
    present = {r["method"] for r in results}
    for name in sorted(present):
        get_method(name)
    return [name for name in method_names() if name in present]


def budget_means(results: list[dict[str, Any]], budgets: tuple[float, ...]) -> dict[str, list[float | None]]:
    """Method (:func:`fleet_methods`) -> its mean held-out mIoU over the finished scenes at each budget (None: no
    finite value)."""
    means: dict[str, list[float | None]] = {}
    for method in fleet_methods(results):
        finished = [r for r in results if r["method"] == method and r["status"] == "finished"]
        column = []
        for budget in budgets:
            values = [v for v in (at_budget(r, budget) for r in finished) if np.isfinite(v)]
            column.append(float(np.mean(values)) if values else None)
        means[method] = column
    return means


def budget_table(results: list[dict[str, Any]], budgets: tuple[float, ...],
                 percent: Callable[[float | None], str]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the table: one row per budget (seconds), one column per method, its cells ``percent``
    of the mean held-out mIoU."""
    means = budget_means(results, budgets)
    header = ["budget s", *(f"{get_method(m).style.label} mIoU % ({results_inputs(results, m) or UNRECORDED})"
                            for m in means)]
    rows = [[f"{b:.0f}", *(percent(column[i]) for column in means.values())] for i, b in enumerate(budgets)]
    return header, rows


def step_zero(results: list[dict[str, Any]]) -> str:
    """What budget 0 is for each method of ``results``: ``zero-shot for S-Ray finetune, ...; untrained for ...``."""
    methods = [get_method(m) for m in fleet_methods(results)]
    parts = [(kind, [m.style.label for m in methods if (m.zero_shot is not None) == shot])
             for kind, shot in (("zero-shot", True), ("untrained", False))]
    return "; ".join(f"{kind} for {', '.join(labels)}" for kind, labels in parts if labels)
