"""What a training sweep leaves when its study returns: finished child runs, the best model, table and chart.

Idempotent across resumes: child runs already finished (``SweepRecord.finished_children``) are not touched
again, and the best trial is registered once, when no trial is left unfinished.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from sray.platform.checkpoints.folders import CheckpointManager
from sray.platform.config.train_config import TrainConfig
from sray.platform.sweep.options import SweepOptions
from sray.platform.sweep.outcomes import REASONS, TrialOutcome
from sray.platform.sweep.prepare import PreparedSweep
from sray.platform.sweep.report import best_trial, write_tables
from sray.platform.sweep.sweep_record import write_sweep_record
from sray.platform.sweep.tracking import finish_child, finish_parent, register_best, sweep_alias
from sray.platform.sweep.training_trial import TIME_ATTR, job_name
from sray.platform.tracking.tracker import RunHandle, Tracker
from sray.platform.viz.sweep_chart import TrialCurve, write_sweep_chart

CHART_FILE = "metric_vs_time.png"
"""The chart in a sweep's folder."""


@dataclass
class SweepResult:
    """Where a sweep stands after a run of its driver."""

    folder: Path
    """The sweep's folder."""
    outcomes: list[TrialOutcome]
    """Every trial's outcome, in plan order."""
    best: TrialOutcome | None
    """The best finished trial, if any."""
    files: list[Path]
    """The results table's files and the chart."""
    parent: RunHandle
    """The sweep's parent run."""
    complete: bool
    """False when some trial is unfinished (``--resume`` continues it)."""


def final_checkpoint(cfg: TrainConfig) -> Path | None:
    """The latest checkpoint of a trial's training job (None when it never saved one)."""
    root = cfg.job_dir() / "checkpoints"
    return CheckpointManager(root).latest() if root.is_dir() else None


def _chart(prepared: PreparedSweep, outcomes: list[TrialOutcome], options: SweepOptions,
           best: TrialOutcome | None) -> Path | None:
    def label(o: TrialOutcome) -> str:
        """Legend text: the key and the values, by field name."""
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
    """Finish the ended trials' child runs, register the best trial when the sweep is complete, write the
    table and chart into the sweep's folder, log them to the parent run and close it."""
    record, options = prepared.record, SweepOptions(**prepared.record.options)
    experiment = prepared.configs[0].run.experiment
    for outcome, cfg in zip(outcomes, prepared.configs):
        if outcome.reason == "unfinished" or outcome.key in record.finished_children:
            continue
        finish_child(tracker, experiment, parent, record.name, job_name(record.name, outcome.key), outcome,
                     final_checkpoint(cfg))
        record.finished_children.append(outcome.key)
        write_sweep_record(prepared.folder, record)
    complete = all(o.reason != "unfinished" for o in outcomes)
    best = best_trial(outcomes, options.metric, options.mode)
    checkpoint = final_checkpoint(prepared.configs[list(record.plan).index(best.key)]) if best else None
    if complete and checkpoint is not None and record.register_as and not record.registered:
        register_best(tracker, experiment, job_name(record.name, best.key), checkpoint, record.register_as,
                      sweep_alias(record.name))
        record.registered = best.key
        write_sweep_record(prepared.folder, record)
    files = write_tables(prepared.folder, outcomes, options.metric, options.mode, TIME_ATTR, f"Sweep {record.name}")
    chart = _chart(prepared, outcomes, options, best)
    files += [chart] if chart else []
    counts = Counter(o.reason for o in outcomes)
    metrics = {f"trials/{r}": float(counts[r]) for r in REASONS}
    if best is not None:
        metrics[f"best/{options.metric}"] = best.last_value(options.metric)
    finish_parent(tracker, parent, files, metrics, "FINISHED" if complete else "KILLED")
    return SweepResult(prepared.folder, outcomes, best, files, parent, complete)
