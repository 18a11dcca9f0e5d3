"""A study's files per trial, under ``<study>/trials/<key>/``, each with one writer; writes are atomic, and a
history line cut by a killed driver is skipped on reading.

* ``trial.json`` (:class:`TrialRecord`), by the trial's own process (or, before any trial runs, by
  ``incremental``): each launch's start and, once the point function returned or raised, the outcome. A trial
  with an outcome never runs again, whatever state Tune saved.
* ``stop_request.json``, by the driver: end the trial early (``by`` the scheduler or the wall-time budget, ``at``
  a value of the time attribute); the trial stops itself, so its workers hand their resources back.
* ``history.jsonl``, appended by the driver: every reported result, with the running time across launches
  (``time_s``) and the launch number.
"""

from __future__ import annotations

import contextlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json

TRIALS = "trials"
"""Folder of the study holding one folder per trial key."""
RECORD = "trial.json"
HISTORY = "history.jsonl"
STOP_REQUEST = "stop_request.json"
FINISHED, ERRORED = "finished", "errored"
"""Outcomes a trial's own process records."""
BY_SCHEDULER, BY_BUDGET = "scheduler", "budget"
"""Who asked a trial to stop early."""


def trial_folder(study: Path | str, key: str) -> Path:
    """``<study>/trials/<key>``."""
    return Path(study) / TRIALS / key


@dataclass
class TrialRecord:
    """What the trial's own process recorded (``trial.json``)."""

    launches: list[float] = field(default_factory=list)
    """Unix time at which each launch of the trial began, in order."""
    outcome: str | None = None
    """:data:`FINISHED` or :data:`ERRORED` once the point function returned or raised; None before."""
    error: str = ""
    """``Type: message`` of the error of an errored trial."""
    result: dict[str, Any] | None = None
    """What the point function returned (a JSON-able dict); None when nothing."""
    imported: str = ""
    """The file an imported result was read from ('' when the trial computed it)."""

    @property
    def done(self) -> bool:
        """True once the trial has an outcome (it never runs again)."""
        return self.outcome is not None


def read_record(folder: Path) -> TrialRecord:
    """The trial's record (an empty one before its first launch)."""
    path = Path(folder) / RECORD
    if not path.is_file():
        return TrialRecord()
    return TrialRecord(**json.loads(path.read_text()))


def write_record(folder: Path, record: TrialRecord) -> None:
    """Replace the trial's record atomically."""
    atomic_write_json(Path(folder) / RECORD, asdict(record))


def request_stop(folder: Path, by: str, at: float | None) -> None:
    """Ask the trial to stop early (``by`` :data:`BY_SCHEDULER` or :data:`BY_BUDGET`, at time attribute ``at``)."""
    atomic_write_json(Path(folder) / STOP_REQUEST, {"by": by, "at": at})


def read_stop_request(folder: Path) -> dict[str, Any] | None:
    """The trial's stop request, or None when nobody asked it to stop."""
    path = Path(folder) / STOP_REQUEST
    return json.loads(path.read_text()) if path.is_file() else None


def append_history(folder: Path, entry: dict[str, Any]) -> None:
    """Append one reported result (a JSON line) to the trial's history."""
    with open(Path(folder) / HISTORY, "a") as f:
        f.write(json.dumps(entry) + "\n")


def read_history(folder: Path) -> list[dict[str, Any]]:
    """The trial's reported results in order; a line cut short by a killed driver is skipped."""
    path = Path(folder) / HISTORY
    if not path.is_file():
        return []
    entries = []
    for line in path.read_text().splitlines():
        with contextlib.suppress(ValueError):
            entries.append(json.loads(line))
    return entries
