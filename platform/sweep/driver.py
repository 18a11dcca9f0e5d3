"""``sray sweep``'s driver: check, start (or resume) and finish a training sweep on the study engine, with a parent
run and each trial's job run as its child (ended with ``sray.stop_reason``, ``sray.stop_note``, checkpoint, status);
once none is unfinished, the best trial's checkpoint gets the sweep's alias. Idempotent; tracking errors warn."""

from __future__ import annotations

import logging
import os
import re
from collections import Counter
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import ray
import torch

from sray.platform.checkpoints.folders import CheckpointManager
from sray.platform.common.ray_address import check_ray_address
from sray.platform.config.train_config import TrainConfig
from sray.platform.sweep.engine import run_study
from sray.platform.sweep.options import SweepOptions, SweepRequest
from sray.platform.sweep.outcomes import REASONS, TrialOutcome, best_trial, write_tables
from sray.platform.sweep.prepare import (RECORD_FILE, PreparedSweep, check_inputs, plan_concurrency, prepare_sweep,
                                        read_sweep_record, reload_sweep, study_settings, write_sweep_record)
from sray.platform.sweep.training_trial import TIME_ATTR, job_name, run_training_trial
from sray.platform.tracking.registry import get_tracker
from sray.platform.tracking.tracker import RunHandle, Tracker
from sray.platform.train.launcher import init_ray
from sray.platform.train.resources import NodeResources, live_nodes
from sray.platform.viz.sweep_chart import TrialCurve, write_sweep_chart

log = logging.getLogger(__name__)

CHART_FILE = "metric_vs_time.png"
STATUS = {"finished": "FINISHED", "stopped": "KILLED", "errored": "FAILED", "unfinished": "KILLED"}
"""Run status of a child run by the reason its trial ended."""


@dataclass
class SweepResult:
    """Where a sweep stands after a run of its driver."""

    folder: Path
    outcomes: list[TrialOutcome]
    """Every trial's outcome, in plan order."""
    best: TrialOutcome | None
    files: list[Path]
    """The results table's files and the chart."""
    parent: RunHandle
    complete: bool
    """False when some trial is unfinished (``--resume`` continues it)."""


def start_parent(prepared: PreparedSweep, tracker: Tracker) -> RunHandle:
    """The sweep's parent run, noted in the sweep's record."""
    record = prepared.record
    run = tracker.start_run(prepared.configs[0].run.experiment, record.name,
                            tags={"sray.kind": "sweep", "sray.sweep_dir": str(prepared.folder)})
    logger = tracker.logger(run)
    logger.log_params({"sweep": {"options": record.options, "params": dict(p.split("=", 1) for p in record.params)}})
    logger.log_artifact(prepared.folder / RECORD_FILE)
    logger.flush(force=True)
    record.parent_run_id = run.run_id
    write_sweep_record(prepared.folder, record)
    return run


def finish_child(tracker: Tracker, experiment: str, parent: RunHandle, sweep: str, outcome: TrialOutcome,
                 checkpoint: Path | None) -> None:
    """Tag, store the final checkpoint of and close the child run of one trial (made here when its job made none)."""
    try:
        name = job_name(sweep, outcome.key)
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
    """Register the final checkpoint of the best trial's run ``name`` as a version of ``model`` at ``alias``."""
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


def final_checkpoint(cfg: TrainConfig) -> Path | None:
    """The latest checkpoint of a trial's training job (None when it never saved one)."""
    root = cfg.job_dir() / "checkpoints"
    return CheckpointManager(root).latest() if root.is_dir() else None


def _chart(prepared: PreparedSweep, outcomes: list[TrialOutcome], options: SweepOptions,
           best: TrialOutcome | None) -> Path | None:
    def label(o: TrialOutcome) -> str:
        return o.key + ": " + ", ".join(f"{k.split('.')[-1]}={v:.3g}" if isinstance(v, float) else
                                        f"{k.split('.')[-1]}={v}" for k, v in o.point.items())

    curves = [TrialCurve(label(o), [e["time_s"] for e in o.history if options.metric in e],
                         [e[options.metric] for e in o.history if options.metric in e], o.reason) for o in outcomes]
    if not any(c.values for c in curves):
        return None
    scheduler = "ASHA" if options.scheduler == "asha" else "no early stopping"
    silent = [f"{o.key} ({o.reason})" for o, c in zip(outcomes, curves) if not c.values]
    return write_sweep_chart(
        curves, options.metric, f"Sweep {prepared.record.name}: {options.metric} against trial time ({scheduler})",
        "One line per trial: the metric at each validation against the trial's running time (across resumes). "
        "A large X marks where the scheduler cut a trial; a dot ends a finished trial; dotted lines errored or "
        "unfinished ones. Thickest line: the best finished trial."
        + (f" Not drawn (no report): {', '.join(silent)}." if silent else ""),
        prepared.folder / CHART_FILE, best=label(best) if best else None)


def finish_sweep(prepared: PreparedSweep, outcomes: list[TrialOutcome], tracker: Tracker,
                 parent: RunHandle) -> SweepResult:
    """Finish the ended trials' child runs and the parent run, register the best trial, write table and chart."""
    record, options = prepared.record, SweepOptions(**prepared.record.options)
    experiment = prepared.configs[0].run.experiment
    for outcome, cfg in zip(outcomes, prepared.configs):
        if outcome.reason == "unfinished" or outcome.key in record.finished_children:
            continue
        finish_child(tracker, experiment, parent, record.name, outcome, final_checkpoint(cfg))
        record.finished_children.append(outcome.key)
        write_sweep_record(prepared.folder, record)
    complete = all(o.reason != "unfinished" for o in outcomes)
    best = best_trial(outcomes, options.metric, options.mode)
    checkpoint = final_checkpoint(prepared.configs[list(record.plan).index(best.key)]) if best else None
    if complete and checkpoint is not None and record.register_as and not record.registered:
        alias = "sweep-" + re.sub(r"[^A-Za-z0-9_-]+", "-", record.name).strip("-")  # characters an alias takes
        register_best(tracker, experiment, job_name(record.name, best.key), checkpoint, record.register_as, alias)
        record.registered = best.key
        write_sweep_record(prepared.folder, record)
    files = write_tables(prepared.folder, outcomes, options.metric, options.mode, TIME_ATTR, f"Sweep {record.name}")
    chart = _chart(prepared, outcomes, options, best)
    files += [chart] if chart else []
    counts = Counter(o.reason for o in outcomes)
    metrics = {f"trials/{r}": float(counts[r]) for r in REASONS}
    if best is not None:
        metrics[f"best/{options.metric}"] = best.last_value(options.metric)
    logger = tracker.logger(parent)
    for path in files:
        logger.log_artifact(path, "results")
    logger.log_metrics(metrics, step=0)
    logger.close("FINISHED" if complete else "KILLED")
    return SweepResult(prepared.folder, outcomes, best, files, parent, complete)


def _concurrency(prepared: PreparedSweep, address: str | None) -> int:
    """Trials at once on the cluster at ``address`` (checked, then joined) or on the local Ray ``init_ray`` would
    start (every CPU of this machine, its CUDA GPUs), known before it starts."""
    if address:
        check_ray_address(address)
        init_ray(address)
    nodes = live_nodes() if ray.is_initialized() else [
        NodeResources("this machine", float(os.cpu_count() or 1), float(torch.cuda.device_count()))]
    return plan_concurrency(int(prepared.record.options["max_concurrent"]), prepared.configs, nodes)


def _run(prepared: PreparedSweep, tracker: Tracker, parent: RunHandle, concurrency: int, address: str | None,
         resume: bool) -> SweepResult:
    init_ray(address)
    record = prepared.record
    settings = study_settings(prepared, concurrency)
    print(f"[sweep] {record.name}: {len(record.plan)} trial(s), {concurrency} at a time, in {prepared.folder}\n"
          f"[sweep] {tracker.label} parent run: {parent.ui_url}" + (f"  ({parent.ui_hint})" if parent.ui_hint else ""),
          flush=True)
    point_fn = partial(run_training_trial, base=record.base, sweep=record.name, parent=parent)
    outcomes = run_study(record.plan, point_fn, settings, resume=resume)
    return finish_sweep(prepared, outcomes, tracker, parent)


def run_sweep(request: SweepRequest, address: str | None = None) -> SweepResult:
    """Check a new sweep (the cluster's room too) before anything is written, then run it (``resume_sweep`` goes on)."""
    prepared = prepare_sweep(request)
    concurrency = _concurrency(prepared, address)
    check_inputs(prepared)
    tracker = get_tracker(prepared.record.tracker, prepared.record.store)
    prepared.folder.mkdir(parents=True)
    write_sweep_record(prepared.folder, prepared.record)
    parent = start_parent(prepared, tracker)
    return _run(prepared, tracker, parent, concurrency, address, resume=False)


def resume_sweep(out: Path, name: str, address: str | None = None) -> SweepResult:
    """Continue the sweep ``<out>/<name>``: unfinished trials run again (from their last checkpoint), others stay."""
    folder = (Path(out) / name).resolve()
    prepared = reload_sweep(read_sweep_record(folder), folder)
    concurrency = _concurrency(prepared, address)
    tracker = get_tracker(prepared.record.tracker, prepared.record.store)
    if prepared.record.parent_run_id:
        parent = tracker.get_run(prepared.record.parent_run_id)
        tracker.set_status(parent, "RUNNING")
    else:  # the first driver died between its record and its parent run
        parent = start_parent(prepared, tracker)
    print(f"[sweep] resuming {name} from {folder / RECORD_FILE}", flush=True)
    return _run(prepared, tracker, parent, concurrency, address, resume=True)
