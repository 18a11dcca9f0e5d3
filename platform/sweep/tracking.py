"""A sweep's tracked runs, through the tracker interface: one parent run, one nested child run per trial.

A training trial's child run is its training job's own run (params, metrics, renders, nested under the
parent by the launcher). When the sweep ends, each child is finished here: tags naming the sweep, the trial,
why it ended (``sray.stop_reason``: finished, stopped, errored, unfinished) and the error or who stopped it
(``sray.stop_note``), its final checkpoint as the artifact ``checkpoint/``, and a status (FINISHED, KILLED
for stopped or unfinished, FAILED). A trial that failed before its job started gets a child run made here,
with its values as params. The best trial's checkpoint is registered under the sweep's alias. Tracking never
stops a sweep: problems only warn.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sray.platform.sweep.outcomes import TrialOutcome
from sray.platform.tracking.tracker import RunHandle, Tracker

log = logging.getLogger(__name__)

STATUS = {"finished": "FINISHED", "stopped": "KILLED", "errored": "FAILED", "unfinished": "KILLED"}
"""Run status of a child run by the reason its trial ended."""


def sweep_alias(sweep: str) -> str:
    """The registry alias of a sweep's best model: ``sweep-<name>`` with other characters than letters,
    digits, ``_`` and ``-`` turned into ``-``."""
    return "sweep-" + re.sub(r"[^A-Za-z0-9_-]+", "-", sweep).strip("-")


def start_parent(tracker: Tracker, experiment: str, sweep: str, folder: Path, params: Mapping[str, Any],
                 record_file: Path) -> RunHandle:
    """The sweep's parent run, with the sweep's options and distributions as params and its record as artifact."""
    run = tracker.start_run(experiment, sweep, tags={"sray.kind": "sweep", "sray.sweep_dir": str(folder)})
    logger = tracker.logger(run)
    logger.log_params(params)
    logger.log_artifact(record_file)
    logger.flush(force=True)
    return run


def reopen_parent(tracker: Tracker, run_id: str) -> RunHandle:
    """The recorded parent run, marked RUNNING again (a resumed sweep)."""
    run = tracker.get_run(run_id)
    tracker.set_status(run, "RUNNING")
    return run


def finish_child(tracker: Tracker, experiment: str, parent: RunHandle, sweep: str, name: str,
                 outcome: TrialOutcome, checkpoint: Path | None) -> None:
    """Tag, store the final checkpoint of and close the child run ``name`` of one trial of ``sweep`` (made
    here when the trial failed before its job made one)."""
    try:
        run = tracker.find_run(experiment, name)
        if run is None:
            run = tracker.start_run(experiment, name, parent=parent)
            tracker.logger(run).log_params(outcome.point)
        tracker.set_tags(run, {"sray.kind": "sweep-trial", "sray.sweep": sweep, "sray.trial": outcome.key,
                               "sray.stop_reason": outcome.reason, "sray.stop_note": outcome.note[:4000]})
        logger = tracker.logger(run)
        if checkpoint is not None:
            logger.log_artifact(checkpoint, "checkpoint")
        logger.close(STATUS[outcome.reason])
    except Exception as e:  # noqa: BLE001 - tracking problems never stop a sweep
        log.warning("could not finish the %s run of trial %s: %s", tracker.label, outcome.key, e)


def register_best(tracker: Tracker, experiment: str, name: str, checkpoint: Path, model: str, alias: str) -> None:
    """Register the best trial's final checkpoint (its child run ``name``) as a version of ``model`` reachable
    as ``model@alias``."""
    try:
        run = tracker.find_run(experiment, name)
        if run is None:
            raise LookupError(f"no run named {name!r} in experiment {experiment!r}")
        logger = tracker.logger(run)
        version = logger.register_model(checkpoint, model, alias=alias)
        logger.close("FINISHED")
        print(f"[sweep] best trial's model registered as {model}@{alias} (version {version})", flush=True)
    except Exception as e:  # noqa: BLE001 - tracking problems never stop a sweep
        log.warning("could not register the best trial's model %s@%s: %s", model, alias, e)


def finish_parent(tracker: Tracker, parent: RunHandle, files: list[Path], metrics: Mapping[str, float],
                  status: str) -> None:
    """Log the results table files and the chart, summary metrics, and close the parent run with ``status``."""
    logger = tracker.logger(parent)
    for path in files:
        logger.log_artifact(path, "results")
    logger.log_metrics(metrics, step=0)
    logger.close(status)
