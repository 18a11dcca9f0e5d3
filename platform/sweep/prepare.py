"""A training sweep checked before anything starts or is written (refusal: one line) and its record ``sweep.json``."""

from __future__ import annotations

import copy
import dataclasses
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json
from sray.platform.config.train_config import TrainConfig, apply_override
from sray.platform.sweep.options import SweepOptions, SweepRequest
from sray.platform.sweep.spec import SpecError, build_plan, check_unique, with_seeds
from sray.platform.sweep.study import StudySettings
from sray.platform.sweep.training_trial import TIME_ATTR, check_metric, check_params, job_name, trial_config
from sray.platform.tracking.registry import get_tracker
from sray.platform.train.inputs import check_request, check_shards, check_tracker
from sray.platform.train.resources import InfeasibleRequest, NodeResources, workers_per_node

RECORD_FILE = "sweep.json"
FORMAT = "sray-sweep"


@dataclass
class SweepRecord:
    """A sweep's stored description and progress."""

    name: str
    options: dict[str, Any]
    """``SweepOptions`` as a dict."""
    params: list[str]
    """Each swept field as ``section.field=SPEC``."""
    plan: dict[str, dict[str, Any]]
    """Trial key -> field path -> value."""
    base: dict[str, Any]
    """The trials' common training config (``TrainConfig.to_dict``)."""
    register_as: str
    """Model name the best trial's checkpoint is registered under ('' = not registered)."""
    tracker: str
    store: str
    """The tracker's store (MLflow: the tracking URI)."""
    parent_run_id: str = ""
    """Id of the sweep's parent run ('' before it exists)."""
    finished_children: list[str] = field(default_factory=list)
    """Keys of the trials whose child runs have been finished (tags, checkpoint, status)."""
    registered: str = ""
    """Key of the trial registered as the best model ('' = none yet)."""
    format: str = FORMAT


def write_sweep_record(folder: Path, record: SweepRecord) -> Path:
    """Write ``sweep.json`` atomically; returns its path."""
    path = Path(folder) / RECORD_FILE
    atomic_write_json(path, dataclasses.asdict(record))
    return path


def read_sweep_record(folder: Path) -> SweepRecord:
    """The sweep recorded in ``folder``; FileNotFoundError or ValueError naming the file and the fix."""
    path = Path(folder) / RECORD_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing, so there is no sweep {Path(folder).name!r} to resume; check "
                                "--resume NAME and --out")
    raw = json.loads(path.read_text())
    if raw.get("format") != FORMAT:
        raise ValueError(f"{path}: field 'format' is {raw.get('format')!r}, expected {FORMAT!r}")
    return SweepRecord(**raw)


TRIAL_RESOURCES = {"memory": 1.0}
"""What Tune reserves for a training trial's own process, which only drives its job: one byte of memory (Tune
refuses an empty request; any CPU would be taken from the trial's own workers)."""


def trials_at_once(cfg: TrainConfig, nodes: list[NodeResources]) -> int:
    """Trials of ``cfg``'s size the nodes host at once (0 when not even one fits)."""
    workers = sum(workers_per_node(n, cfg.run.cpus_per_worker, cfg.run.gpus_per_worker) for n in nodes)
    return workers // cfg.run.workers


def _size(cfg: TrainConfig) -> str:
    return f"{cfg.run.workers} worker(s) of {cfg.run.cpus_per_worker:g} CPU + {cfg.run.gpus_per_worker:g} GPU"


def plan_concurrency(requested: int, configs: list[TrainConfig], nodes: list[NodeResources]) -> int:
    """Trials at once on ``nodes``: ``requested`` if every size in ``configs`` fits that many (0: as many as fit)."""
    have = (f"{sum(n.cpus for n in nodes):g} CPUs and {sum(n.gpus for n in nodes):g} GPUs on {len(nodes)} "
            "node(s)")
    fits = [(trials_at_once(cfg, nodes), cfg) for cfg in configs]
    for n, cfg in fits:
        if n == 0:
            raise InfeasibleRequest(
                f"run.workers / run.cpus_per_worker / run.gpus_per_worker: a trial trains {_size(cfg)}, which the "
                f"cluster ({have}) cannot host at once; lower --workers, --set run.cpus_per_worker or "
                "--gpus-per-worker, or join a larger cluster with --address")
    fit, widest = min(fits, key=lambda pair: pair[0])
    if requested == 0:
        return fit
    if requested > fit:
        raise InfeasibleRequest(
            f"--max-concurrent {requested}: each trial trains {_size(widest)} and the cluster ({have}) fits {fit} "
            f"such trial(s) at once; use --max-concurrent {fit} (or 0 for as many as fit), fewer workers per trial "
            "(--workers), or fractional CPUs (--set run.cpus_per_worker=0.5)")
    return requested


NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
"""A sweep name: a folder name and a run-name prefix (letters, digits, ``. _ -``)."""
JOBS = "jobs"
"""Folder of a sweep holding its trials' training jobs."""


@dataclass
class PreparedSweep:
    """A checked sweep, ready to run (or to resume)."""

    folder: Path
    record: SweepRecord
    configs: list[TrainConfig]
    """Every trial's training config, in plan order."""


def sweep_base(base: TrainConfig, options: SweepOptions, folder: Path, store: str) -> TrainConfig:
    """The trials' common config: budgets applied, jobs under ``<folder>/jobs``, absolute paths, no registration."""
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
    """The engine's settings of a prepared sweep: ASHA on the step, up to the largest budget, first rung at grace."""
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
    """Check a new sweep; its record and trial configs (nothing written, Ray not started; see :func:`check_inputs`)."""
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
    configs = [trial_config(base, point, job_name(request.name, key)) for key, point in plan.items()]
    _check_trials(configs, request.options)
    record = SweepRecord(name=request.name, options=dataclasses.asdict(request.options),
                         params=[f"{p.path}={p.spec}" for p in params], plan=plan, base=base.to_dict(),
                         register_as=request.base.run.register_model, tracker=tracker.name, store=tracker.store)
    return PreparedSweep(folder, record, configs)


def check_inputs(prepared: PreparedSweep) -> None:
    """The trials' shard folder and tracking store are usable (the store's schema is made now, before any trial)."""
    base = prepared.configs[0]
    check_shards(Path(base.data.shards))
    check_tracker(base)


def reload_sweep(record: SweepRecord, folder: Path) -> PreparedSweep:
    """A recorded sweep, ready to resume: its trial configs rebuilt from the record."""
    base = TrainConfig.from_dict(record.base)
    return PreparedSweep(folder, record, [trial_config(base, point, job_name(record.name, key))
                                          for key, point in record.plan.items()])
