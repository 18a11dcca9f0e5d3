"""Everything about a training sweep checked before anything starts or is written.

:func:`prepare_sweep` turns a request into the sweep's record and every trial's config, refusing in one line what
cannot run: a malformed or unknown parameter, a value a field rejects, a metric the trials do not report, a
scheduler that could never stop anything, a taken name, a missing shard folder or tracking store.
"""

from __future__ import annotations

import copy
import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path

from sray.platform.config.train_config import TrainConfig, apply_override
from sray.platform.sweep.capacity import TRIAL_RESOURCES
from sray.platform.sweep.study import StudySettings
from sray.platform.sweep.options import SweepOptions
from sray.platform.sweep.options import SweepRequest
from sray.platform.sweep.plan import build_plan, with_seeds
from sray.platform.sweep.spec import SpecError, check_unique
from sray.platform.sweep.sweep_record import SweepRecord
from sray.platform.sweep.training_trial import TIME_ATTR, check_metric, check_params, trial_job_config
from sray.platform.tracking.registry import get_tracker
from sray.platform.train.inputs import check_request, check_shards, check_tracker

NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
"""A sweep name: a folder name and a run-name prefix (letters, digits, ``. _ -``)."""
JOBS = "jobs"
"""Folder of a sweep holding its trials' training jobs."""


@dataclass
class PreparedSweep:
    """A checked sweep, ready to run (or to resume)."""

    folder: Path
    record: SweepRecord
    """What ``sweep.json`` holds."""
    configs: list[TrainConfig]
    """Every trial's training config, in plan order."""


def sweep_base(base: TrainConfig, options: SweepOptions, folder: Path, store: str) -> TrainConfig:
    """The trials' common config: budgets applied, jobs under ``<folder>/jobs``, absolute shard folder, the
    resolved tracking store, no per-trial model registration (the sweep registers its best trial)."""
    cfg = copy.deepcopy(base)
    for path, value in (("optim.steps", options.steps), ("optim.cpu_seconds", options.cpu_seconds)):
        if value:
            apply_override(cfg, f"{path}={value}")
    cfg.run.output_dir = str(folder / JOBS)
    cfg.data.shards = str(Path(cfg.data.shards).resolve())
    cfg.run.tracking_uri = store
    cfg.run.register_model = ""
    return cfg


def _asha_span(configs: list[TrainConfig], options: SweepOptions) -> tuple[int, int]:
    return max(c.optim.steps for c in configs), options.grace or min(c.run.ckpt_every for c in configs)


def study_settings(prepared: PreparedSweep, max_concurrent: int) -> StudySettings:
    """The engine's settings of a prepared sweep: ASHA on the step up to the largest step budget, first rung at
    ``--grace`` (default: the smallest checkpoint interval, where trials first report)."""
    o = SweepOptions(**prepared.record.options)
    max_t, grace = _asha_span(prepared.configs, o)
    return StudySettings(folder=prepared.folder, metric=o.metric, mode=o.mode, time_attr=TIME_ATTR,
                         max_concurrent=max_concurrent, trial_resources=TRIAL_RESOURCES, scheduler=o.scheduler,
                         max_t=max_t, grace=grace, reduction_factor=o.reduction_factor,
                         wall_budget_s=60.0 * o.minutes)


def _check_trials(configs: list[TrainConfig], options: SweepOptions) -> None:
    check_metric(options.metric, configs)
    for cfg in configs:
        check_request(cfg.run.workers, cfg.run.cpus_per_worker, cfg.run.gpus_per_worker, cfg.run.precision)
    budget, grace = _asha_span(configs, options)
    if options.scheduler == "asha" and grace >= budget:
        raise SpecError(f"--grace {grace}: ASHA first compares trials at {grace} steps (default: run.ckpt_every), "
                        f"but the budget is {budget} steps; lower --grace or run.ckpt_every, raise --steps, or use "
                        "--scheduler none")


def prepare_sweep(request: SweepRequest) -> PreparedSweep:
    """Check a new sweep and build its record and trial configs (nothing is written, Ray is not started);
    SpecError, InputError, FileExistsError. The data and the store are checked by :func:`check_inputs`."""
    if not NAME.match(request.name):
        raise SpecError(f"--name {request.name!r}: use letters, digits, '.', '_' and '-' (it names a folder)")
    folder = (Path(request.out) / request.name).resolve()
    if folder.exists():
        raise FileExistsError(f"{folder}: a sweep called {request.name!r} exists; continue it with "
                              f"`sray sweep --resume {request.name}` or pick another --name")
    params = with_seeds(request.params, request.options.seeds)
    if not params:
        raise SpecError("no parameter to sweep: pass --param section.field=SPEC or a spec file with 'params:'")
    check_unique(params)
    tracker = get_tracker(request.base.run.tracker, request.base.run.tracking_uri)
    base = sweep_base(request.base, request.options, folder, tracker.store)
    check_params(base, params)
    plan = build_plan(params, request.options.samples, request.options.seed)
    configs = [trial_job_config(base, point, request.name, key) for key, point in plan.items()]
    _check_trials(configs, request.options)
    record = SweepRecord(name=request.name, options=dataclasses.asdict(request.options),
                         params=[f"{p.path}={p.spec}" for p in params], plan=plan, base=base.to_dict(),
                         register_as=request.base.run.register_model, tracker=tracker.name, store=tracker.store)
    return PreparedSweep(folder, record, configs)


def check_inputs(prepared: PreparedSweep) -> None:
    """The trials' shard folder and tracking store are usable (InputError naming the fix); the store's schema is
    made now, before any trial fans out."""
    base = prepared.configs[0]
    check_shards(Path(base.data.shards))
    check_tracker(base)


def reload_sweep(record: SweepRecord, folder: Path) -> PreparedSweep:
    """A recorded sweep, ready to resume: its trial configs rebuilt from the record."""
    base = TrainConfig.from_dict(record.base)
    return PreparedSweep(folder, record, [trial_job_config(base, point, record.name, key)
                                          for key, point in record.plan.items()])
