"""A study completed launch after launch (``sray lab study``, ``sray stability``): each launch runs, as a new Tune
experiment, only the trials without a result (errored ones again); the trials' records are the store, and a result
an earlier harness stored elsewhere can be imported as a finished trial.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sray.platform.sweep.engine import run_study
from sray.platform.sweep.outcomes import TrialOutcome, collect_outcomes
from sray.platform.sweep.study import (ERRORED, FINISHED, TRIALS, PointFunction, StudySettings, TrialRecord,
                                       read_record, trial_folder, write_record)


def import_result(study: Path, key: str, result: dict[str, Any], source: Path) -> bool:
    """Record ``result``, read from ``source``, as the finished trial ``key`` unless it finished; True if imported."""
    folder = trial_folder(study, key)
    record = read_record(folder)
    if record.outcome == FINISHED:
        return False
    folder.mkdir(parents=True, exist_ok=True)
    write_record(folder, TrialRecord(launches=record.launches, outcome=FINISHED, result=result,
                                     imported=str(source)))
    return True


def stored_results(study: Path) -> dict[str, dict[str, Any]]:
    """The result of every finished trial in ``study`` (imported ones included), by key in sorted order."""
    root = Path(study) / TRIALS
    if not root.is_dir():
        return {}
    results = {}
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        record = read_record(folder)
        if record.outcome == FINISHED and record.result is not None:
            results[folder.name] = record.result
    return results


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
