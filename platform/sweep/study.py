"""What the study engine (``sray.platform.sweep.engine``) and a point function share: the study's settings
and the trial's context."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import ray.tune

from sray.platform.sweep.trial_files import read_stop_request


@dataclass(frozen=True)
class TrialContext:
    """What a point function knows of its trial."""

    key: str
    """The trial's key in the plan (``t003``)."""
    folder: Path
    """The trial's own folder (``<study>/trials/<key>``), for anything it writes."""
    launch: int
    """0 on the trial's first launch; n on its (n+1)-th, after a study was resumed."""

    def stop_requested(self) -> bool:
        """True once the scheduler or the wall-time budget asked this trial to end now."""
        return read_stop_request(self.folder) is not None

    def report(self, metrics: Mapping[str, float]) -> None:
        """Send one result to Tune (a point function that is not a Ray Train job reports this way)."""
        ray.tune.report(dict(metrics))


PointFunction = Callable[[dict[str, Any], TrialContext], "dict[str, Any] | None"]
"""Runs the trial of one point; reports through Tune; may return its result (a JSON-able dict, kept in the
trial's record); raises on failure."""


@dataclass(frozen=True)
class StudySettings:
    """How the engine runs a study's trials."""

    folder: Path
    """The study's folder: ``trials/`` (one folder per key) and ``tune/`` (Tune's state)."""
    metric: str
    """Result key trials are compared by."""
    mode: str
    """``max`` or ``min``."""
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
    """Unix time after which no trial starts (0 = no limit): a later trial returns at once and stays unfinished
    for the next launch. Running trials go on."""
    reuse_actors: bool = False
    """Run the trials in one process (Tune's ``reuse_actors``), for short trials that keep what they loaded. Off:
    a fresh process per trial (a trial that trains with Accelerate needs one)."""
    label: str = "sweep"
    """Prefix of the study's progress lines (``[sweep] t001 started: ...``)."""
