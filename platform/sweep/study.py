"""What the study engine and a point function share: settings, the trial's context and its files under
``<study>/trials/<key>/``, each with one writer, written atomically: ``trial.json`` (:class:`TrialRecord`, by the
trial: launches, outcome), ``stop_request.json`` (by the driver; the trial stops itself, so its workers hand their
resources back), ``history.jsonl`` (by the driver: every result with the running time; a cut line is skipped)."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import ray.tune

from sray.data_tools.atomic import atomic_write_json

TRIALS = "trials"
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
    """:data:`FINISHED` or :data:`ERRORED` once the point function returned or raised (it never runs again)."""
    error: str = ""
    """``Type: message`` of the error of an errored trial."""
    result: dict[str, Any] | None = None
    """What the point function returned (a JSON-able dict); None when nothing."""
    imported: str = ""
    """The file an earlier harness imported the result from ('' otherwise; nothing imports now)."""


def read_record(folder: Path) -> TrialRecord:
    """The trial's record (an empty one before its first launch)."""
    path = Path(folder) / RECORD
    return TrialRecord(**json.loads(path.read_text())) if path.is_file() else TrialRecord()


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


@dataclass(frozen=True)
class TrialContext:
    """What a point function knows of its trial."""

    key: str
    """The trial's key in the plan (``t003``)."""
    folder: Path
    """The trial's own folder (``<study>/trials/<key>``), for anything it writes."""

    def stop_requested(self) -> bool:
        """True once the scheduler or the wall-time budget asked this trial to end now."""
        return read_stop_request(self.folder) is not None

    def report(self, metrics: Mapping[str, float]) -> None:
        """Send one result to Tune (a point function that is not a Ray Train job reports this way)."""
        ray.tune.report(dict(metrics))


PointFunction = Callable[[dict[str, Any], TrialContext], "dict[str, Any] | None"]
"""Runs one point's trial, reports to Tune, may return a JSON-able result (kept in its record), raises on failure."""


@dataclass(frozen=True)
class StudySettings:
    """How the engine runs a study's trials."""

    folder: Path
    """The study's folder: ``trials/`` (one folder per key) and ``tune/`` (Tune's state)."""
    metric: str
    """Result key trials are compared by."""
    mode: str
    time_attr: str = "training_iteration"
    """Result key measuring a trial's progress (a training job's ``step``): the scheduler's time axis."""
    max_concurrent: int = 1
    trial_resources: Mapping[str, float] = field(default_factory=lambda: {"CPU": 1.0})
    """What Tune reserves for one trial's process (a training trial's workers reserve their own)."""
    scheduler: str = "none"
    """``asha`` (early stopping on ``time_attr``) or ``none``."""
    max_t: float = 0.0
    """ASHA: the most ``time_attr`` a trial reaches (its budget)."""
    grace: float = 1.0
    """ASHA: ``time_attr`` before a trial can be stopped."""
    reduction_factor: float = 3.0
    """ASHA: about 1 in this many trials continues at each rung."""
    wall_budget_s: float = 0.0
    """A trial is asked to stop once it has run this long across its launches (0 = no limit)."""
    start_by: float = 0.0
    """Unix time after which no trial starts (0 = none); a later one returns at once, unfinished for the next launch."""
    reuse_actors: bool = False
    """One process for all trials (Tune's ``reuse_actors``), for short ones; off for trials training with Accelerate."""
    label: str = "sweep"
    """Prefix of the study's progress lines (``[sweep] t001 started: ...``)."""
