"""``sray sweep``'s driver: check, start (or resume) and finish a training sweep on the study engine.

Everything is checked first (``prepare``), then how many trials the cluster runs at once (``capacity``; for the
local default before Ray even starts), and only then is anything written: the sweep's folder and record, the
parent run. Every trial is a real training job (``training_trial``) nested under that run.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

from sray.platform.common.ray_address import check_ray_address
from sray.platform.sweep.capacity import expected_nodes, plan_concurrency
from sray.platform.sweep.engine import run_study
from sray.platform.sweep.finish import SweepResult, finish_sweep, start_parent
from sray.platform.sweep.options import SweepRequest
from sray.platform.sweep.prepare import PreparedSweep, check_inputs, prepare_sweep, reload_sweep, study_settings
from sray.platform.sweep.sweep_record import RECORD_FILE, read_sweep_record, write_sweep_record
from sray.platform.sweep.training_trial import run_training_trial
from sray.platform.tracking.registry import get_tracker
from sray.platform.tracking.tracker import RunHandle, Tracker
from sray.platform.train.launcher import init_ray


def _concurrency(prepared: PreparedSweep, address: str | None) -> int:
    """Trials at once on the cluster at ``address`` (checked, then joined) or the local one (before it starts)."""
    if address:
        check_ray_address(address)
        init_ray(address)
    requested = int(prepared.record.options["max_concurrent"])
    return plan_concurrency(requested, prepared.configs, expected_nodes())


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
    """Check and run a new sweep to its end (or until interrupted: then ``resume_sweep`` continues it)."""
    prepared = prepare_sweep(request)
    concurrency = _concurrency(prepared, address)
    check_inputs(prepared)
    tracker = get_tracker(prepared.record.tracker, prepared.record.store)
    prepared.folder.mkdir(parents=True)
    write_sweep_record(prepared.folder, prepared.record)
    parent = start_parent(prepared, tracker)
    return _run(prepared, tracker, parent, concurrency, address, resume=False)


def resume_sweep(out: Path, name: str, address: str | None = None) -> SweepResult:
    """Continue the sweep ``<out>/<name>``: unfinished trials run again (a training job from its last
    checkpoint), finished and errored ones are kept."""
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
