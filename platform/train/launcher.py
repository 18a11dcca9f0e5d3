"""The driver side of ``sray train``: Ray, resources, the tracked run, the TorchTrainer, Ctrl-C."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import ray
import ray.train
from ray.train.torch import TorchTrainer

from sray.data_tools.loader.class_stats import BALANCE_MODES, balanced_weights, shard_pixel_counts
from sray.platform.checkpoints.folders import CheckpointManager, load_checkpoint, read_meta
from sray.platform.common.fault_hook import propagated_env
from sray.platform.common.progress import progress_env
from sray.platform.common.ray_env import SETUP_HOOK, TRAIN_POLL_ENV, TRAIN_WORKER_ENV
from sray.platform.config.train_config import CONFIG_FILE, TrainConfig
from sray.platform.tracking.registry import get_tracker
from sray.platform.tracking.tracker import RunHandle
from sray.platform.train.inputs import check_train_inputs
from sray.platform.train.resources import check_feasible
from sray.platform.train.validation import validation_protocol
from sray.platform.train.worker import STOP_FILE, train_worker


@dataclass
class TrainOutcome:
    """Where a finished (or stopped) job left its results; ``status``: FINISHED, KILLED or FAILED."""

    job_dir: Path
    run: RunHandle
    best_checkpoint: Path | None
    latest_checkpoint: Path | None
    status: str


def unique_name(cfg: TrainConfig) -> str:
    """``cfg.run.name`` (refused when taken), else ``<recipe>-<UTC timestamp>``."""
    out = Path(cfg.run.output_dir)
    if cfg.run.name:
        if (out / cfg.run.name).exists():
            raise FileExistsError(f"{out / cfg.run.name}: a job called {cfg.run.name!r} exists; continue it with "
                                  f"`sray train --resume {cfg.run.name}` or pick another --name")
        return cfg.run.name
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    name, n = f"{cfg.recipe}-{stamp}", 1
    while (out / name).exists():
        n += 1
        name = f"{cfg.recipe}-{stamp}-{n}"
    return name


def set_class_weights(cfg: TrainConfig) -> None:
    """Fill ``cfg.model.class_weights`` as ``data.class_balance`` asks from the train scenes' labelled pixels."""
    if cfg.data.class_balance not in BALANCE_MODES:
        raise ValueError(f"data.class_balance is {cfg.data.class_balance!r}; use one of {BALANCE_MODES}")
    if cfg.data.class_balance == "none" or cfg.model.class_weights:
        return
    names, per_scene = shard_pixel_counts(Path(cfg.data.shards), roles=("train",))
    if len(names) != cfg.model.n_classes:
        raise ValueError(f"{cfg.data.shards}/manifest.json: {len(names)} classes, model.n_classes is "
                         f"{cfg.model.n_classes}; train on data of the model's label space")
    counts = sum(per_scene.values())[:-1]  # (n_classes,): the ignore id's pixels are left out
    weights = tuple(balanced_weights(counts, cfg.data.class_balance))
    cfg.model = dataclasses.replace(cfg.model, class_weights=weights)


LOCAL_WORKER_ENV = dict(TRAIN_POLL_ENV)
"""Environment a local Ray's workers inherit where unset (not ``THP_MEM_ALLOC_ENABLE``: docs/performance.md)."""


def init_ray(address: str | None, num_cpus: int | None = None) -> None:
    """Join a cluster at ``address`` or start a local Ray in-process, with :data:`LOCAL_WORKER_ENV`."""
    if ray.is_initialized():
        return
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    quiet = {"worker_process_setup_hook": SETUP_HOOK}
    if address:
        ray.init(address=address, runtime_env=quiet)
        return
    for key, value in LOCAL_WORKER_ENV.items():
        os.environ.setdefault(key, value)
    # started with SIGINT ignored, Ray's processes leave Ctrl-C to this driver, which stops the workers cleanly
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        ray.init(address="local", num_cpus=num_cpus or os.cpu_count(), include_dashboard=False, runtime_env=quiet,
                 _temp_dir=tempfile.mkdtemp(prefix="ray", dir="/tmp"), object_store_memory=200 * 2**20,
                 log_to_driver=True)
    finally:
        signal.signal(signal.SIGINT, previous)


def _install_stop_handler(job_dir: Path) -> Any:
    """First Ctrl-C: ask the workers to checkpoint and stop. Second: abort now."""
    def handler(signum: int, frame: Any) -> None:
        stop = job_dir / STOP_FILE
        if stop.exists():
            raise KeyboardInterrupt
        stop.touch()
        print("\n[sray] stopping after the current step with a checkpoint (Ctrl-C again to abort) ...", flush=True)

    return signal.signal(signal.SIGINT, handler)


def launch_training(cfg: TrainConfig, address: str | None = None, resume: bool = False, *,
                    parent: RunHandle | None = None, callbacks: Sequence[Any] = ()) -> TrainOutcome:
    """Run a training job to the end or a clean stop; ``resume`` continues ``cfg.run.name``; ``parent``: the run it
    nests under; ``callbacks``: Ray Train callbacks (a Tune trial's, off the main thread: no Ctrl-C handler then)."""
    check_train_inputs(cfg, resume=resume, address=address)  # before Ray: one line, never retried
    tracker = get_tracker(cfg.run.tracker, cfg.run.tracking_uri)
    if not resume:
        cfg.run.name = unique_name(cfg)
    cfg.run.output_dir = str(Path(cfg.run.output_dir).resolve())
    cfg.data.shards = str(Path(cfg.data.shards).resolve())
    if not resume:
        set_class_weights(cfg)
    job_dir = cfg.job_dir()
    job_dir.mkdir(parents=True, exist_ok=True)
    (job_dir / STOP_FILE).unlink(missing_ok=True)
    (job_dir / CONFIG_FILE).write_text(json.dumps(cfg.to_dict(), indent=1) + "\n")

    init_ray(address)
    check_feasible(cfg.run.workers, cfg.run.cpus_per_worker, cfg.run.gpus_per_worker)
    cfg.run.tracking_uri = tracker.store
    protocol = validation_protocol(cfg)
    tags = {"sray.recipe": cfg.recipe, "sray.job_dir": str(job_dir), "sray.protocol": protocol.describe()}
    if resume:
        run = tracker.resume_run(cfg.run.experiment, cfg.run.name)
    else:
        run = tracker.start_run(cfg.run.experiment, cfg.run.name, tags=tags, parent=parent)
        logger = tracker.logger(run)  # the config file and, once, the validation protocol (params protocol.*)
        logger.log_artifact(job_dir / CONFIG_FILE)
        logger.log_params({"protocol": protocol.to_json()})
        logger.flush(force=True)
    print(f"[sray] job {cfg.run.name}: checkpoints in {job_dir / 'checkpoints'}\n"
          f"[sray] {tracker.label} run: {run.ui_url}" + (f"  ({run.ui_hint})" if run.ui_hint else ""), flush=True)

    latest = CheckpointManager(job_dir / "checkpoints").latest() if resume else None
    gpus = {"GPU": cfg.run.gpus_per_worker} if cfg.run.gpus_per_worker > 0 else {}
    trainer = TorchTrainer(
        train_worker, train_loop_config={"config": cfg.to_dict(), "run": dataclasses.asdict(run),
                                         "resume_from": str(latest) if latest is not None else None},
        scaling_config=ray.train.ScalingConfig(num_workers=cfg.run.workers, use_gpu=bool(gpus),
                                               resources_per_worker={"CPU": cfg.run.cpus_per_worker, **gpus}),
        run_config=ray.train.RunConfig(name=cfg.run.name, storage_path=str(job_dir / "ray"), callbacks=list(callbacks),
                                       failure_config=ray.train.FailureConfig(max_failures=cfg.run.max_failures),
                                       worker_runtime_env={"env_vars": TRAIN_WORKER_ENV | propagated_env()
                                                                       | progress_env()}))
    on_main_thread = threading.current_thread() is threading.main_thread()
    previous = _install_stop_handler(job_dir) if on_main_thread else None
    status = "FAILED"
    try:
        _fit_in_thread(trainer)
        status = "KILLED" if (job_dir / STOP_FILE).exists() or not budget_spent(job_dir, cfg) else "FINISHED"
    except KeyboardInterrupt:
        status = "KILLED"
        raise
    finally:
        if on_main_thread:
            signal.signal(signal.SIGINT, previous)
        tracker.end_run(run, status)
    manager = CheckpointManager(job_dir / "checkpoints")
    outcome = TrainOutcome(job_dir, run, manager.best(), manager.latest(), status)
    word = {"KILLED": "stopped", "FINISHED": "finished"}.get(status, status.lower())
    print(f"[sray] {word}: best checkpoint {outcome.best_checkpoint}, latest {outcome.latest_checkpoint}\n"
          f"[sray] {tracker.label} run: {run.ui_url}", flush=True)
    return outcome


def _fit_in_thread(trainer: Any) -> None:
    """``trainer.fit()`` off the main thread, so that Ray Train installs no SIGINT handler (ours stops cleanly)."""
    failure: list[BaseException] = []

    def target() -> None:
        try:
            trainer.fit()
        except BaseException as e:  # noqa: BLE001 - handed to the main thread
            failure.append(e)

    thread = threading.Thread(target=target, name="sray-fit", daemon=True)
    thread.start()
    while thread.is_alive():
        thread.join(timeout=0.5)
    if failure:
        raise failure[0]


def budget_spent(job_dir: Path, cfg: TrainConfig) -> bool:
    """Whether the job's last checkpoint reached its step cap or its CPU-second budget (``optim.cpu_seconds``)."""
    latest = CheckpointManager(job_dir / "checkpoints").latest()
    if latest is None:
        return False
    if read_meta(latest)["step"] >= cfg.optim.steps:
        return True
    budget = cfg.optim.cpu_seconds
    return budget > 0 and load_checkpoint(latest)["counters"]["cpu_seconds"] >= budget
