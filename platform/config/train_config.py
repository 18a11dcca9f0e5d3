"""The full, typed configuration of a training job (what a recipe returns, what the tracker records)."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sray.data_tools.loader.augment import Augmentation
from sray.model.config import SRayConfig
from sray.model.runtime import Runtime
from sray.platform.config.held_out_render import HeldOutRender
from sray.platform.config.overrides import set_field
from sray.platform.config.stored_format import CONFIG_VERSION, VERSION_KEY, from_plain, outdated


@dataclass
class DataSettings:
    """Where the shards are and how training samples are drawn from them."""

    shards: str = "outputs/demo/shards"
    """Folder holding ``manifest.json`` and the webdataset shards (``sray data shard``)."""
    top_k: int = 12
    """Source views (``model.n_source`` of them) are drawn from this many top-ranked neighbours of the query view."""
    rays_per_batch: int = 1024
    """Rays per training step and rank (paper: 1024)."""
    loader_workers: int = 1
    """DataLoader worker processes per rank."""
    visit_samples: int = 16
    """Consecutive samples each loader worker draws from one scene before it picks its next scene at random
    (1 = scenes interleaved step by step; larger reuses a decoded scene more, ``shard_loader``)."""
    cache_scenes: int = 2
    """Scenes each loader worker keeps decoded-ready in memory (encoded views; least recently used dropped)."""
    epoch_steps: int = 0
    """Steps per loader epoch. Epoch e's samples are drawn from ``(run.seed, e, rank)``, so this, not how often the
    job checkpoints, sets the data order when it is > 0; 0 = one epoch per ``run.ckpt_every`` steps. A job resumed
    mid-epoch regenerates the epoch's samples up to its step, so a long epoch makes a resume slower."""
    val_views_per_scene: int = 2
    """Held-out views rendered per scene at each validation (in chunks of ``runtime.chunk`` rays)."""
    held_out: HeldOutRender = field(default_factory=lambda: HeldOutRender(n_source=0, stride=2, fast_stride=1))
    """How validation renders and scores its views: the model's own source count, every 2nd pixel to keep it cheap,
    the fast render on those pixels; set field by field: ``--set data.held_out.render=full``."""
    val_scenes: int = 0
    """Scenes of each role (train, unseen test) validated, the first ones by name; 0 = all of them."""
    class_balance: str = "none"
    """Semantic loss weights: ``none`` (the paper), ``inverse-sqrt`` or ``inverse`` of the training scenes' pixel
    frequencies (``sray.data_tools.loader.class_stats``), computed at the start, stored as ``model.class_weights``."""
    aug: Augmentation = field(default_factory=Augmentation)
    """Training-sample augmentation (``sray.data_tools.loader.augment``; all off by default), field by field."""

    def __post_init__(self) -> None:
        """ValueError naming a field out of range."""
        if self.visit_samples < 1 or self.cache_scenes < 1:
            raise ValueError(f"train config: data.visit_samples ({self.visit_samples}) and data.cache_scenes "
                             f"({self.cache_scenes}) must be >= 1")
        if self.epoch_steps < 0:
            raise ValueError(f"train config: data.epoch_steps is {self.epoch_steps}; give a number of steps, or 0 for "
                             "one loader epoch per run.ckpt_every steps")
        self.held_out.check(lambda field: f"train config: data.held_out.{field}")


@dataclass
class OptimSettings:
    """Optimiser, schedule and stability guards."""

    steps: int = 250_000
    """Total optimiser steps (paper: 250k)."""
    lr: float = 1e-3
    """Initial Adam learning rate (paper: 1e-3)."""
    lr_final: float = 5e-5
    """Learning rate reached at the last step by exponential decay (paper: 5e-5)."""
    warmup_steps: int = 0
    """Linear warm-up steps before the decay starts."""
    grad_clip: float = 1.0
    """Global gradient-norm clipping threshold (0 disables clipping)."""
    cpu_seconds: float = 0.0
    """Stop once the job has spent this many CPU seconds, summed over its ranks and their loader processes
    (``sray.platform.train.cpu_clock``), or at ``steps``, whichever comes first; the learning-rate decay then
    follows the larger of the step and the CPU fraction (set ``steps`` as a cap). 0 = steps only."""
    warmup_2d_steps: int = 0
    """The first this many steps train the encoder and its source-view head on the source views' labels alone
    (nothing rendered; a departure from the paper, docs/model.md); they count toward ``steps``; 0 = off."""
    max_nonfinite_in_row: int = 20
    """A non-finite loss or gradient skips the step; this many in a row stop the job."""


@dataclass
class RunSettings:
    """Cadence, precision, placement and where results go."""

    name: str = ""
    """Job name; unique per job (a timestamp is appended when empty or clashing)."""
    output_dir: str = "outputs/train"
    """Root folder of checkpoints and Ray Train run state; a job writes under <output_dir>/<name>."""
    experiment: str = "sray-train"
    """Experiment (group of runs) the job's run belongs to."""
    tracker: str = "mlflow"
    """Tracker the job logs to, by registry name (``sray.platform.tracking.registry``)."""
    tracking_uri: str = ""
    """The tracker's store (MLflow: the tracking URI); empty = its default store in the working directory."""
    precision: str = "no"
    """Mixed precision: ``no`` (fp32), ``bf16`` (autocast, CPU and CUDA) or ``fp16`` (loss scaling, CUDA)."""
    workers: int = 2
    """Ray Train workers (one Accelerate process each)."""
    cpus_per_worker: float = 1.0
    """CPUs reserved per worker."""
    gpus_per_worker: float = 0.0
    """GPUs per worker (0 = CPU training). With more than one worker, a whole number: NCCL refuses two
    ranks on one GPU, so a fraction is refused before Ray starts (one worker may take a fraction)."""
    seed: int = 0
    """Seed of parameters, sampling and data order."""
    log_every: int = 10
    """Training metrics are logged (batched) every this many steps."""
    val_every: int = 500
    """Validation (held-out views of train scenes + zero-shot on unseen test scenes) cadence."""
    ckpt_every: int = 500
    """Checkpoint cadence in steps (and always at the end)."""
    keep_checkpoints: int = 2
    """Recent checkpoints kept besides the best."""
    max_failures: int = 2
    """Worker-group restarts Ray Train attempts after a worker dies."""
    system_metrics_s: float = 0.0
    """Seconds between records of each node's system metrics (``system/node<k>/...``) by its first worker; 0 = off."""
    register_model: str = "sray"
    """Name the final checkpoint is registered under in the tracker's model registry ('' = do not register)."""


@dataclass
class TrainConfig:
    """Everything a training job needs; recipes return one, ``--set a.b=value`` overrides fields."""

    recipe: str = "synth-small"
    """Name of the recipe this config came from."""
    model: SRayConfig = field(default_factory=SRayConfig)
    """The network and its loss (paper defaults): what the job's checkpoints hold besides their weights."""
    data: DataSettings = field(default_factory=DataSettings)
    """Shards and sample assembly."""
    optim: OptimSettings = field(default_factory=OptimSettings)
    """Optimiser and schedule."""
    run: RunSettings = field(default_factory=RunSettings)
    """Cadence, precision, placement, outputs."""
    runtime: Runtime = field(default_factory=Runtime)
    """How the network is run (``sray.model.runtime``), set field by field: ``--set runtime.chunk=4096``."""

    def __post_init__(self) -> None:
        """Reject settings the sections cannot train with (:meth:`check`)."""
        self.check()

    def check(self) -> None:
        """ValueError naming a field out of range, or settings of sections that cannot train together: fp16 with a
        loss in pieces smaller than the batch (a piece's gradients are not loss-scaled, so small ones could
        underflow), a 2D warm-up without the source-view head it trains."""
        self.model.__post_init__()
        self.data.__post_init__()
        if self.optim.cpu_seconds < 0:
            raise ValueError(f"train config: optim.cpu_seconds is {self.optim.cpu_seconds}; use 0 (steps only) or a "
                             "positive CPU-second budget")
        warmup, src_sem = self.optim.warmup_2d_steps, self.model.lambda_src_sem
        if warmup < 0 or (warmup > 0 and src_sem <= 0):
            raise ValueError(f"train config: optim.warmup_2d_steps is {warmup}; it must be >= 0, and a warm-up "
                             "trains the source-view head, so it needs model.lambda_src_sem > 0 "
                             f"(is {src_sem}). Set model.lambda_src_sem=1 or optim.warmup_2d_steps=0.")
        piece, rays = self.runtime.train_piece, self.data.rays_per_batch
        if self.run.precision == "fp16" and 0 < piece < rays:
            raise ValueError(f"train config: runtime.train_piece is {piece} (< data.rays_per_batch {rays}) with "
                             "run.precision=fp16; a piece's gradients are not loss-scaled. "
                             "Set runtime.train_piece=0 (the whole batch on a GPU) or run.precision=bf16.")

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (JSON/YAML-safe; tuples become lists) with its ``format_version``."""
        return {VERSION_KEY: CONFIG_VERSION, **dataclasses.asdict(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_dict`, today's format only (``stored_format``)."""
        if (version := d.get(VERSION_KEY, 1)) != CONFIG_VERSION:
            raise outdated("train config", version, CONFIG_VERSION)
        return from_plain(cls, {k: v for k, v in d.items() if k != VERSION_KEY}, "train config")

    def job_dir(self) -> Path:
        """Folder of this job's checkpoints and run state."""
        return Path(self.run.output_dir).resolve() / self.run.name


def apply_override(cfg: TrainConfig, assignment: str) -> None:
    """Apply one ``section.field=value`` override in place (``overrides.set_field``): ValueError names an unknown
    section or field and lists the valid ones, or a value the network cannot run with (the old value stays)."""
    set_field(cfg, assignment, "optim.lr=5e-4", cfg.check)


CONFIG_FILE = "config.json"
"""The job's full config, written into its folder (and logged as an artifact)."""


def load_job_config(output_dir: str, name: str) -> TrainConfig:
    """The saved config of an existing job (for ``--resume``); errors name the file and the fix."""
    path = Path(output_dir) / name / CONFIG_FILE
    if not path.exists():
        raise FileNotFoundError(f"{path}: no job called {name!r} under {output_dir}; "
                                "check --name/--resume and the output folder (run.output_dir)")
    try:
        return TrainConfig.from_dict(json.loads(path.read_text()))
    except ValueError as e:
        raise type(e)(f"{path}: {e}") from None
