"""Why each trial of a study ended, read back from its files (``trial_files``) and Tune's errors.

Reasons: ``finished`` (the point function returned by itself, or the trial reached its wall-time budget),
``stopped`` (stopped early by the scheduler), ``errored`` (it raised, or its process died), ``unfinished``
(the study was interrupted before the trial ended: ``--resume`` runs it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sray.platform.sweep.trial_files import (BY_SCHEDULER, ERRORED, FINISHED, TrialRecord, read_history, read_record,
                                             read_stop_request, trial_folder)

REASONS = ("finished", "stopped", "errored", "unfinished")
"""Why a trial ended, in the order tables list them."""


@dataclass
class TrialOutcome:
    """One trial of a study: its point, why it ended, what it reported."""

    key: str
    """The trial's key in the plan."""
    point: dict[str, Any]
    """Its values (field path -> value)."""
    reason: str
    """One of :data:`REASONS`."""
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
    """(reason, note). A stop request that came with the trial's own last report (``last_at``, the time attribute
    there) found nothing left to stop: the trial ended by itself."""
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
    """Every trial's outcome, in plan order; ``tune_errors``: key -> error of trials Tune marked failed;
    ``time_attr``: the result key measuring a trial's progress."""
    outcomes = []
    for key, point in plan.items():
        folder = trial_folder(study, key)
        record, history = read_record(folder), read_history(folder)
        reached = [e[time_attr] for e in history if time_attr in e]
        reason, note = _reason(record, read_stop_request(folder), tune_errors.get(key),
                               reached[-1] if reached else None)
        outcomes.append(TrialOutcome(key, dict(point), reason, note, history, len(record.launches), record.result))
    return outcomes
