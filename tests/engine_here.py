"""The study engine with Ray Tune replaced by its own trial wrapper run in this process: the harnesses' tests run
plans of trials this way (a trial that raises is recorded and the next one runs, as Tune's fail_fast=False)."""

from __future__ import annotations

from sray.platform.sweep.engine import _run_trial, _TrialJob
from sray.platform.sweep.outcomes import TrialOutcome, collect_outcomes
from sray.platform.sweep.study import PointFunction, StudySettings


def run_study_here(plan: dict, point_fn: PointFunction, settings: StudySettings,
                   resume: bool = False) -> list[TrialOutcome]:
    """``engine.run_study``'s contract, every trial run in turn by the engine's trial wrapper in this process."""
    job = _TrialJob(point_fn, plan, str(settings.folder), {}, settings.start_by)
    for key in plan:
        try:
            _run_trial({"key": key}, job)
        except RuntimeError:
            pass
    return collect_outcomes(settings.folder, plan, {}, settings.time_attr)
