"""A study's results table (Markdown, CSV, JSON with every trial's history): a row per trial in plan order. The
best trial is the finished one whose last value of the metric is best (a stopped trial was judged worse by the
scheduler; the last value is the model its final checkpoint holds).
"""

from __future__ import annotations

import csv
import io
from collections import Counter
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json, atomic_write_text
from sray.platform.sweep.outcomes import REASONS, TrialOutcome

TABLE_FILES = ("results.md", "results.csv", "results.json")
"""The table's files in a study's folder."""


def best_trial(outcomes: list[TrialOutcome], metric: str, mode: str) -> TrialOutcome | None:
    """The finished trial with the best last value of ``metric`` (``mode`` max or min), None when none has one."""
    scored = [o for o in outcomes if o.reason == "finished" and o.last_value(metric) is not None]
    if not scored:
        return None
    sign = 1.0 if mode == "max" else -1.0
    return max(scored, key=lambda o: sign * o.last_value(metric))


def _best_value(outcome: TrialOutcome, metric: str, mode: str) -> float | None:
    values = [float(e[metric]) for e in outcome.history if metric in e]
    if not values:
        return None
    return max(values) if mode == "max" else min(values)


def result_rows(outcomes: list[TrialOutcome], metric: str, mode: str, time_attr: str) -> list[dict[str, Any]]:
    """One dict per trial: ``trial``, the point's fields, ``reason``, ``time_attr``, ``time_s``, ``metric``
    (last value), ``best <metric>``, ``launches``, ``note``."""
    return [{"trial": o.key, **o.point, "reason": o.reason, time_attr: o.last.get(time_attr),
             "time_s": o.last.get("time_s"), metric: o.last_value(metric),
             f"best {metric}": _best_value(o, metric, mode), "launches": o.launches, "note": o.note}
            for o in outcomes]


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value).replace("|", "/").replace("\n", " ")


def _markdown(rows: list[dict[str, Any]], title: str, summary: list[str]) -> str:
    columns = list(rows[0]) if rows else ["trial"]
    lines = [f"# {title}", "", *summary, "", "| " + " | ".join(columns) + " |",
             "|" + "|".join(" --- " for _ in columns) + "|"]
    lines += ["| " + " | ".join(_cell(row.get(c)) for c in columns) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _csv(rows: list[dict[str, Any]]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]) if rows else ["trial"])
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def write_tables(folder: Path, outcomes: list[TrialOutcome], metric: str, mode: str, time_attr: str,
                 title: str) -> list[Path]:
    """Write the table files of :data:`TABLE_FILES` into ``folder``; returns their paths."""
    rows = result_rows(outcomes, metric, mode, time_attr)
    best = best_trial(outcomes, metric, mode)
    counts = Counter(o.reason for o in outcomes)
    summary = [f"Metric: `{metric}` ({mode}); trials: "
               + ", ".join(f"{counts[r]} {r}" for r in REASONS if counts[r]) + ".",
               f"Best: {best.key} ({metric} {best.last_value(metric):.4g})." if best else "Best: none finished."]
    paths = [Path(folder) / name for name in TABLE_FILES]
    atomic_write_text(paths[0], _markdown(rows, title, summary))
    atomic_write_text(paths[1], _csv(rows))
    atomic_write_json(paths[2], {"title": title, "metric": metric, "mode": mode, "time_attr": time_attr,
                                 "best": best.key if best else None,
                                 "trials": [row | {"history": o.history} for row, o in zip(rows, outcomes)]})
    return paths
