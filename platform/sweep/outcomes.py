"""Why each trial of a study ended (``finished``: returned or out of wall time; ``stopped`` by the scheduler;
``errored``; ``unfinished``: ``--resume`` runs it), from its files and Tune's errors, and the results table (Markdown,
CSV, JSON with histories). The best trial: the finished one with the best last metric (its final checkpoint's)."""

from __future__ import annotations

import csv
import io
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json, atomic_write_text
from sray.platform.sweep.study import (BY_SCHEDULER, ERRORED, FINISHED, TrialRecord, read_history, read_record,
                                       read_stop_request, trial_folder)

REASONS = ("finished", "stopped", "errored", "unfinished")
"""Why a trial ended, in the order tables list them."""
TABLE_FILES = ("results.md", "results.csv", "results.json")


@dataclass
class TrialOutcome:
    """One trial of a study: its point, why it ended, what it reported."""

    key: str
    point: dict[str, Any]
    """Its values (field path -> value)."""
    reason: str
    note: str = ""
    """The error of an errored trial; who stopped a stopped one and when; '' otherwise."""
    history: list[dict[str, Any]] = field(default_factory=list)
    """Every result it reported, in order (``time_s``: its running time across launches)."""
    launches: int = 0
    """How many times the trial was started (more than one after a resumed study)."""
    result: dict[str, Any] | None = None
    """What the point function returned (or what was imported as its result); None when nothing."""

    @property
    def last(self) -> dict[str, Any]:
        """Its last reported result ({} when it reported nothing)."""
        return self.history[-1] if self.history else {}

    def last_value(self, metric: str) -> float | None:
        """The last reported value of ``metric``, or None."""
        values = [e[metric] for e in self.history if metric in e]
        return float(values[-1]) if values else None


def _reason(record: TrialRecord, stop: dict[str, Any] | None, tune_error: str | None,
            last_at: float | None) -> tuple[str, str]:
    """(reason, note); a stop request made at the trial's own last report (``last_at``) counts as ending by itself."""
    if record.outcome == ERRORED or tune_error is not None:
        return "errored", record.error or tune_error or ""
    too_late = stop is not None and record.outcome == FINISHED and last_at is not None and \
        stop.get("at") is not None and last_at <= stop["at"]
    if stop is not None and not too_late:
        if stop.get("by") == BY_SCHEDULER:
            return "stopped", f"stopped early by the scheduler at {stop.get('at')}"
        return "finished", f"wall-time budget reached at {stop.get('at')}"
    return ("finished" if record.outcome == FINISHED else "unfinished"), ""


def collect_outcomes(study: Path, plan: Mapping[str, Mapping[str, Any]], tune_errors: Mapping[str, str],
                     time_attr: str) -> list[TrialOutcome]:
    """Every trial's outcome, in plan order; ``tune_errors``: key -> error of trials Tune marked failed."""
    outcomes = []
    for key, point in plan.items():
        folder = trial_folder(study, key)
        record, history = read_record(folder), read_history(folder)
        reached = [e[time_attr] for e in history if time_attr in e]
        reason, note = _reason(record, read_stop_request(folder), tune_errors.get(key),
                               reached[-1] if reached else None)
        outcomes.append(TrialOutcome(key, dict(point), reason, note, history, len(record.launches), record.result))
    return outcomes


def best_trial(outcomes: list[TrialOutcome], metric: str, mode: str) -> TrialOutcome | None:
    """The finished trial with the best last value of ``metric`` (``mode`` max or min), None when none has one."""
    scored = [o for o in outcomes if o.reason == "finished" and o.last_value(metric) is not None]
    sign = 1.0 if mode == "max" else -1.0
    return max(scored, key=lambda o: sign * o.last_value(metric), default=None)


def _best_value(outcome: TrialOutcome, metric: str, mode: str) -> float | None:
    values = [float(e[metric]) for e in outcome.history if metric in e]
    return (max if mode == "max" else min)(values, default=None)


def result_rows(outcomes: list[TrialOutcome], metric: str, mode: str, time_attr: str) -> list[dict[str, Any]]:
    """One dict per trial: ``trial``, the point, ``reason``, progress, the last and best metric, launches, note."""
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
