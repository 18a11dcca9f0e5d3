"""The study engine: a plan of trials and a point function, run on Ray Tune, resumable and fault-isolated.

A study is a plan (trial key -> point, the values that make the trial) and a point function
``fn(point, ctx)`` that runs one trial and reports its metrics to Tune: a training job
(``sray.platform.sweep.training_trial``) or anything else a Ray worker can run. The engine

* hands Tune the plan as a grid over its keys (the points themselves were drawn before, so a resumed study
  runs the same trials under the same keys) and wraps the point function so that a trial with an outcome
  (``trial_files.TrialRecord``) never runs again, a trial that raises records its error and the others go
  on (Tune's ``fail_fast`` is off; each trial gets its own process unless ``StudySettings.reuse_actors``),
  and a trial asked to stop early is not started again;
* stops trials early through the scheduler of ``sray.platform.sweep.schedulers`` (ASHA on ``time_attr``) or
  at the wall-time budget (``sray.platform.sweep.trial_log``), each time by a request the trial carries out
  itself;
* restores Tune's own state on ``resume`` (``Tuner.restore``: the trials and their statuses), so finished and
  errored trials stay as they were and unfinished ones start again (a training job from its last checkpoint).
  Tune does not save a scheduler's state: ASHA's rungs start empty in a resumed study. Without ``resume`` a
  new Tune experiment replaces any earlier one in the folder (the trials' own records stay);
* keeps what the point function returns as the trial's result (``TrialRecord.result``), and starts no trial
  after ``StudySettings.start_by``.

Tune checks that every result carries the metric; a training job's last report after a stop request does
not, so the check is off (``TUNE_DISABLE_STRICT_METRIC_CHECKING``) and the scheduler skips such results.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ray import tune

from sray.platform.common.fault_hook import fail_trial_if_listed, propagated_env
from sray.platform.sweep.outcomes import TrialOutcome, collect_outcomes
from sray.platform.sweep.schedulers import build_scheduler
from sray.platform.sweep.study import PointFunction, StudySettings, TrialContext
from sray.platform.sweep.trial_files import (ERRORED, FINISHED, read_record, read_stop_request, trial_folder,
                                             write_record)
from sray.platform.sweep.trial_log import TrialLog

TUNE_FOLDER = "tune"
"""The study's folder holding Tune's experiment state."""
EXPERIMENT = "study"
"""Name of the Tune experiment inside :data:`TUNE_FOLDER`."""


@dataclass(frozen=True)
class _TrialJob:
    """What every trial process is handed, besides its key (Tune's config)."""

    point_fn: PointFunction
    plan: dict[str, dict[str, Any]]
    study: str
    env: dict[str, str]
    start_by: float = 0.0
    """Unix time after which no trial starts (0 = no limit)."""


def _run_trial(config: dict[str, Any], job: _TrialJob) -> None:
    """Tune's function trainable: run the point of ``config["key"]`` unless the trial is done or asked to stop."""
    key = config["key"]
    folder = trial_folder(job.study, key)
    folder.mkdir(parents=True, exist_ok=True)
    record = read_record(folder)
    if record.outcome == ERRORED:
        raise RuntimeError(f"trial {key} errored in an earlier launch: {record.error}")
    if record.done or read_stop_request(folder) is not None:
        return
    if job.start_by and time.time() >= job.start_by:
        return  # stays unfinished: the next launch of the study runs it
    os.environ.update(job.env)
    record.launches.append(time.time())
    write_record(folder, record)
    try:
        fail_trial_if_listed(key)
        result = job.point_fn(job.plan[key], TrialContext(key, folder, len(record.launches) - 1))
    except BaseException as e:
        lines = str(e).strip().splitlines()
        record.outcome, record.error = ERRORED, f"{type(e).__name__}: {lines[-1] if lines else ''}"[:2000]
        write_record(folder, record)
        raise
    record.outcome, record.result = FINISHED, result
    write_record(folder, record)


def _trial_dirname(trial: Any) -> str:
    """Tune's folder of a trial: its key."""
    return str(trial.config["key"])


def run_study(plan: Mapping[str, Mapping[str, Any]], point_fn: PointFunction, settings: StudySettings,
              resume: bool = False) -> list[TrialOutcome]:
    """Run every trial of ``plan`` (Ray already initialised) and return their outcomes, in plan order.

    ``resume``: continue the study in ``settings.folder`` (Tune's saved state when there is any; the trials'
    own records in any case). ``point_fn`` must be picklable (a module-level function or a partial of one).
    """
    os.environ["TUNE_DISABLE_STRICT_METRIC_CHECKING"] = "1"
    job = _TrialJob(point_fn, {k: dict(v) for k, v in plan.items()}, str(settings.folder), propagated_env(),
                    settings.start_by)
    trainable = tune.with_resources(tune.with_parameters(_run_trial, job=job), dict(settings.trial_resources))
    state = settings.folder / TUNE_FOLDER / EXPERIMENT
    if not resume:
        shutil.rmtree(settings.folder / TUNE_FOLDER, ignore_errors=True)
    if resume and tune.Tuner.can_restore(str(state)):
        tuner = tune.Tuner.restore(str(state), trainable, resume_unfinished=True, resume_errored=False,
                                   restart_errored=False)
    else:
        tuner = tune.Tuner(
            trainable, param_space={"key": tune.grid_search(list(plan))},
            tune_config=tune.TuneConfig(metric=settings.metric, mode=settings.mode,
                                        scheduler=build_scheduler(settings), reuse_actors=settings.reuse_actors,
                                        max_concurrent_trials=settings.max_concurrent,
                                        trial_dirname_creator=_trial_dirname),
            run_config=tune.RunConfig(name=EXPERIMENT, storage_path=str(settings.folder / TUNE_FOLDER), verbose=0,
                                      failure_config=tune.FailureConfig(max_failures=0, fail_fast=False),
                                      callbacks=[TrialLog(settings, plan)]))
    grid = tuner.fit()
    errors = {r.config["key"]: f"{type(r.error).__name__}: {r.error}" for r in grid if r.error is not None}
    return collect_outcomes(settings.folder, plan, errors, settings.time_attr)
