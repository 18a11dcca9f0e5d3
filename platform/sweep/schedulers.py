"""Early stopping whose decisions the trials carry out themselves.

Tune carries out a scheduler's STOP by ending the trial's process. A training trial's Ray Train workers then
die with it, but their placement group outlives them: it belongs to the driver's job, and Ray Train's cleaner
for it polls the state API, which a local Ray without the dashboard does not serve (the "Failed to query Ray
Train Controller actor state" warnings), so the next trial would wait forever for the CPUs the dead one still
holds. :class:`GracefulASHA` therefore records the decision as the trial's stop request
(``trial_files.request_stop``) and lets Tune continue; the trial checkpoints, ends its training job (which
hands its workers back) and returns, and the engine reads the request as the reason it stopped.
"""

from __future__ import annotations

from typing import Any

from ray.tune.schedulers import AsyncHyperBandScheduler, TrialScheduler

from sray.platform.sweep.study import StudySettings
from sray.platform.sweep.trial_files import BY_SCHEDULER, read_stop_request, request_stop, trial_folder



class GracefulASHA(AsyncHyperBandScheduler):
    """Asynchronous successive halving (ASHA) that turns STOP into the trial's own stop request."""

    def __init__(self, study: str, **asha: Any) -> None:
        """``study``: the study's folder; ``asha``: ``AsyncHyperBandScheduler``'s arguments."""
        super().__init__(**asha)
        self.study = study

    def on_trial_result(self, tune_controller: Any, trial: Any, result: dict[str, Any]) -> str:
        """ASHA's decision on a result, carried out as a stop request (not at the budget's end, where there is
        nothing left to stop); always CONTINUE for Tune."""
        folder = trial_folder(self.study, trial.config["key"])
        if read_stop_request(folder) is not None:
            return TrialScheduler.CONTINUE
        at = result.get(self._time_attr)
        if super().on_trial_result(tune_controller, trial, result) == TrialScheduler.STOP and \
                at is not None and at < self._max_t:
            request_stop(folder, BY_SCHEDULER, at)
        return TrialScheduler.CONTINUE


def build_scheduler(settings: StudySettings) -> GracefulASHA | None:
    """ASHA on ``settings.time_attr`` for ``scheduler="asha"``; None (Tune's first-in-first-out) for ``none``."""
    if settings.scheduler != "asha":
        return None
    return GracefulASHA(str(settings.folder), time_attr=settings.time_attr, max_t=settings.max_t,
                        grace_period=settings.grace, reduction_factor=settings.reduction_factor,
                        stop_last_trials=False)  # the metric and mode come from Tune's config
