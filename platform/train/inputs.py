"""Check a training job's inputs before Ray starts: one line naming the file or field and the fix, in seconds."""

from __future__ import annotations

from pathlib import Path

from sray.data_tools.shards.manifest import read_manifest
from sray.platform.common.ray_address import check_ray_address
from sray.platform.config.train_config import TrainConfig
from sray.platform.tracking.registry import get_tracker


class InputError(ValueError):
    """A training input is wrong; the message names the file or field and the fix."""


def check_request(workers: int, cpus_per_worker: float, gpus_per_worker: float, precision: str) -> None:
    """The size of the request itself, before any cluster is asked."""
    if workers < 1:
        raise InputError(f"run.workers: must be at least 1, got {workers}; pass --workers 1 or more")
    if cpus_per_worker < 0 or gpus_per_worker < 0:
        raise InputError(f"run.cpus_per_worker / run.gpus_per_worker: must be >= 0, got {cpus_per_worker:g} and "
                         f"{gpus_per_worker:g}")
    if cpus_per_worker == 0 and gpus_per_worker == 0:
        raise InputError("run.cpus_per_worker and run.gpus_per_worker are both 0: each worker needs some CPU or GPU")
    if workers > 1 and gpus_per_worker > 0 and gpus_per_worker != int(gpus_per_worker):
        raise InputError(f"run.gpus_per_worker {gpus_per_worker:g} with {workers} workers: Ray may place two workers "
                         "on one GPU, and NCCL (the GPU backend of distributed training) refuses two ranks on one GPU "
                         "('Duplicate GPU detected'); give each worker whole GPUs (--gpus-per-worker 1), or train on "
                         "a shared GPU with --workers 1")
    if precision == "fp16" and gpus_per_worker == 0:
        raise InputError("--precision fp16 needs CUDA (loss scaling on GPU); on CPU use --precision bf16 or no")


def check_shards(shards: Path) -> None:
    """The shard folder exists and holds a readable ``manifest.json`` naming at least one scene."""
    shards = Path(shards)
    if not shards.is_dir():
        raise InputError(f"{shards}: no such shard folder (data.shards / --data); make one with "
                         "`sray data shard SCENES_DIR --out FOLDER` or pass the folder holding manifest.json")
    try:
        manifest = read_manifest(shards)
    except (FileNotFoundError, ValueError, KeyError, TypeError) as e:
        raise InputError(str(e).splitlines()[0]) from None
    if not manifest.scenes:
        raise InputError(f"{shards / 'manifest.json'}: field 'scenes' is empty; re-run `sray data shard` with scenes")


def check_tracker(cfg: TrainConfig) -> None:
    """The tracker exists and its store answers (a server is asked once, briefly)."""
    try:
        tracker = get_tracker(cfg.run.tracker, cfg.run.tracking_uri)
    except ValueError as e:
        raise InputError(f"run.tracker / --tracker: {e}") from None
    try:
        tracker.ensure_store()
    except (ConnectionError, ValueError, OSError) as e:
        raise InputError(f"run.tracking_uri / --tracking-uri: {str(e).splitlines()[0]}") from None


def check_train_inputs(cfg: TrainConfig, resume: bool = False, address: str | None = None) -> None:
    """Every check, cheapest first; InputError (RayAddressError for the address) on the first problem."""
    check_request(cfg.run.workers, cfg.run.cpus_per_worker, cfg.run.gpus_per_worker, cfg.run.precision)
    config = Path(cfg.run.output_dir).resolve() / cfg.run.name / "config.json"
    if resume and not config.is_file():
        raise InputError(f"{config}: missing, so there is no job {cfg.run.name!r} to resume; check --resume NAME and "
                         "run.output_dir")
    check_shards(Path(cfg.data.shards))
    if address:
        check_ray_address(address)
    check_tracker(cfg)
