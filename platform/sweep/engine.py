"""The study engine: a plan of trials (key -> point) and a point function run on Ray Tune, resumable and
fault-isolated. A trial with an outcome never runs again; one that raises records its error while the others go on;
early stops (ASHA, the wall-time budget) are requests the trial carries out itself; ``resume`` restores Tune's state
(ASHA's rungs start empty). A training job's last report after a stop lacks the metric: Tune's strict check is off.
A study run launch after launch (:func:`run_missing`) runs only the trials without a result (errored ones again),
as a new Tune experiment each time; the records are the store."""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ray import tune
from ray.tune import Callback
from ray.tune.result import AUTO_RESULT_KEYS, DEBUG_METRICS
from ray.tune.schedulers import AsyncHyperBandScheduler, TrialScheduler

from sray.platform.common.fault_hook import error_text, fail_trial_if_listed, propagated_env
from sray.platform.sweep.outcomes import TrialOutcome, collect_outcomes
from sray.platform.sweep.study import (BY_BUDGET, BY_SCHEDULER, ERRORED, FINISHED, PointFunction, StudySettings,
                                       TrialContext, TrialRecord, append_history, read_history, read_record,
                                       read_stop_request, request_stop, trial_folder, write_record)

TUNE_FOLDER = "tune"
EXPERIMENT = "study"
_SKIPPED = frozenset(AUTO_RESULT_KEYS) | frozenset(DEBUG_METRICS)
"""Tune's own bookkeeping keys, left out of the history."""


@dataclass(frozen=True)
class _TrialJob:
    """What every trial process is handed, besides its key (Tune's config)."""

    point_fn: PointFunction
    plan: dict[str, dict[str, Any]]
    study: str
    env: dict[str, str]
    start_by: float = 0.0


def _run_trial(config: dict[str, Any], job: _TrialJob) -> None:
    """Tune's function trainable: run the point of ``config["key"]`` unless the trial is done or asked to stop."""
    key = config["key"]
    folder = trial_folder(job.study, key)
    folder.mkdir(parents=True, exist_ok=True)
    record = read_record(folder)
    if record.outcome == ERRORED:
        raise RuntimeError(f"trial {key} errored in an earlier launch: {record.error}")
    if record.outcome is not None or read_stop_request(folder) is not None:
        return
    if job.start_by and time.time() >= job.start_by:
        return  # stays unfinished: the next launch of the study runs it
    os.environ.update(job.env)
    record.launches.append(time.time())
    write_record(folder, record)
    try:
        fail_trial_if_listed(key)
        result = job.point_fn(job.plan[key], TrialContext(key, folder))
    except BaseException as e:
        record.outcome, record.error = ERRORED, error_text(e)
        write_record(folder, record)
        raise
    record.outcome, record.result = FINISHED, result
    write_record(folder, record)


class GracefulASHA(AsyncHyperBandScheduler):
    """ASHA whose STOP becomes a trial's stop request, always CONTINUE to Tune: a trial Tune ends leaves its placement
    group holding its CPUs (Ray Train's cleaner needs the dashboard); asked, the trial checkpoints and returns."""

    def __init__(self, study: str, **asha: Any) -> None:
        super().__init__(**asha)
        self.study = study

    def on_trial_result(self, tune_controller: Any, trial: Any, result: dict[str, Any]) -> str:
        """ASHA's decision on a result, as a stop request (none at the budget's end: nothing is left to stop)."""
        folder = trial_folder(self.study, trial.config["key"])
        if read_stop_request(folder) is not None:
            return TrialScheduler.CONTINUE
        at = result.get(self._time_attr)
        if super().on_trial_result(tune_controller, trial, result) == TrialScheduler.STOP and \
                at is not None and at < self._max_t:
            request_stop(folder, BY_SCHEDULER, at)
        return TrialScheduler.CONTINUE


class TrialLog(Callback):
    """The driver's record of results (``history.jsonl``), a line per result, the wall-time budget's stop requests."""

    def __init__(self, settings: StudySettings, plan: Mapping[str, Mapping[str, Any]]) -> None:
        self.settings = settings
        self.plan = {k: dict(v) for k, v in plan.items()}
        self._offsets: dict[tuple[str, int], float] = {}

    def __getstate__(self) -> dict[str, Any]:
        """Tune saves its callbacks with the experiment; a restored one measures offsets afresh."""
        return {k: v for k, v in self.__dict__.items() if k != "_offsets"} | {"_offsets": {}}

    def on_trial_start(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        """Print which point a trial runs."""
        key, s = trial.config["key"], self.settings
        if s.start_by and time.time() >= s.start_by:
            print(f"[{s.label}] {key} not started: no trial starts after the study's time limit", flush=True)
            return
        point = self.plan.get(key, {}).items()
        print(f"[{s.label}] {key} started: " + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                                                         for k, v in point), flush=True)

    def on_trial_result(self, iteration: int, trials: list[Any], trial: Any, result: dict[str, Any],
                        **info: Any) -> None:
        """Append the result, with the running time across launches, to the history; enforce the wall-time budget."""
        key, s = trial.config["key"], self.settings
        folder = trial_folder(s.folder, key)
        launch = max(len(read_record(folder).launches) - 1, 0)
        if (key, launch) not in self._offsets:
            earlier = [e["time_s"] for e in read_history(folder) if e.get("launch", 0) < launch]
            self._offsets[(key, launch)] = max(earlier, default=0.0)
        time_s = self._offsets[(key, launch)] + float(result.get("time_total_s", 0.0))
        values = {k: v for k, v in result.items()
                  if k not in _SKIPPED and isinstance(v, (int, float)) and not isinstance(v, bool)}
        append_history(folder, {"launch": launch, "time_s": round(time_s, 3)} | values)
        if s.metric in values:
            print(f"[{s.label}] {key} {s.time_attr} {values.get(s.time_attr)}: {s.metric} "
                  f"{values[s.metric]:.4g} ({time_s:.0f} s)", flush=True)
        if 0 < s.wall_budget_s <= time_s and read_stop_request(folder) is None:
            request_stop(folder, BY_BUDGET, values.get(s.time_attr))
            print(f"[{s.label}] {key} reached its wall-time budget ({s.wall_budget_s:.0f} s): stopping it",
                  flush=True)

    def on_trial_error(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        """Say that a trial failed (its error is in its record and in the results table)."""
        print(f"[{self.settings.label}] {trial.config['key']} errored; the other trials go on", flush=True)


def _trial_dirname(trial: Any) -> str:
    return str(trial.config["key"])


def run_study(plan: Mapping[str, Mapping[str, Any]], point_fn: PointFunction, settings: StudySettings,
              resume: bool = False) -> list[TrialOutcome]:
    """Run every trial of ``plan`` (Ray up, ``point_fn`` picklable); their outcomes in plan order. Without ``resume``
    a new Tune experiment replaces any earlier one (the trials' records stay)."""
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
        scheduler = None if settings.scheduler != "asha" else GracefulASHA(
            str(settings.folder), time_attr=settings.time_attr, max_t=settings.max_t, grace_period=settings.grace,
            reduction_factor=settings.reduction_factor, stop_last_trials=False)  # metric and mode: Tune's config
        tuner = tune.Tuner(
            trainable, param_space={"key": tune.grid_search(list(plan))},
            tune_config=tune.TuneConfig(metric=settings.metric, mode=settings.mode, scheduler=scheduler,
                                        reuse_actors=settings.reuse_actors,
                                        max_concurrent_trials=settings.max_concurrent,
                                        trial_dirname_creator=_trial_dirname),
            run_config=tune.RunConfig(name=EXPERIMENT, storage_path=str(settings.folder / TUNE_FOLDER), verbose=0,
                                      failure_config=tune.FailureConfig(max_failures=0, fail_fast=False),
                                      callbacks=[TrialLog(settings, plan)]))
    grid = tuner.fit()
    errors = {r.config["key"]: f"{type(r.error).__name__}: {r.error}" for r in grid if r.error is not None}
    return collect_outcomes(settings.folder, plan, errors, settings.time_attr)


def missing(study: Path, plan: Mapping[str, Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """The trials of ``plan`` without a finished outcome, in plan order (Ray must be running to run any)."""
    return {k: dict(v) for k, v in plan.items() if read_record(trial_folder(study, k)).outcome != FINISHED}


def run_missing(plan: Mapping[str, Mapping[str, Any]], point_fn: PointFunction,
                settings: StudySettings) -> list[TrialOutcome]:
    """Run the trials of ``plan`` without a result (none after ``settings.start_by``); every outcome, in plan order."""
    todo = missing(settings.folder, plan)
    ran: dict[str, TrialOutcome] = {}
    if todo and not (settings.start_by and time.time() >= settings.start_by):
        for key in todo:
            folder = trial_folder(settings.folder, key)
            record = read_record(folder)
            if record.outcome == ERRORED:
                print(f"[{settings.label}] {key} errored in an earlier launch ({record.error}): running it again",
                      flush=True)
                write_record(folder, TrialRecord(launches=record.launches))
        ran = {o.key: o for o in run_study(todo, point_fn, settings)}
    return [ran.get(o.key, o) for o in collect_outcomes(settings.folder, plan, {}, settings.time_attr)]
