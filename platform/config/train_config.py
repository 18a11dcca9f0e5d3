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
from sray.platform.config.optim_settings import OptimSettings
from sray.platform.config.overrides import set_field
from sray.platform.config.stored_format import CONFIG_VERSION, VERSION_KEY, check_version, from_plain

PRECISIONS = ("no", "bf16", "fp16")
"""Mixed-precision modes: fp32, bfloat16 autocast (CPU and CUDA), fp16 with loss scaling (CUDA)."""


@dataclass
class DataSettings:
    """Where the shards are and how training samples are drawn from them."""

    shards: str = "outputs/demo/shards"
    """Folder holding ``manifest.json`` and the webdataset shards (``sray data shard``)."""
    top_k: int = 12
    """Source views (``model.n_source`` of them) are drawn from this many top-ranked neighbours
    of the query view."""
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
    """How validation renders and scores its views (``sray.platform.config.held_out_render``): the model's own
    source count, every 2nd pixel to keep it cheap, the fast render on those pixels; set field by field:
    ``--set data.held_out.render=full``."""
    val_scenes: int = 0
    """Scenes of each role (train, unseen test) validated, the first ones by name; 0 = all of them
    (a run over many scenes keeps its validations cheap with a few)."""
    class_balance: str = "none"
    """Class-frequency-aware semantic loss: ``none`` (the paper), ``inverse-sqrt`` or ``inverse``
    weights from the training scenes' pixel frequencies (``sray.data_tools.loader.class_stats``), computed
    when the job starts and stored as ``model.class_weights``."""
    aug: Augmentation = field(default_factory=Augmentation)
    """Training-sample augmentation (``sray.data_tools.loader.augment``: source colour jitter and noise,
    random source count and source resolution; every option off by default), set field by
    field: ``--set data.aug.colour_ev=0.3``."""

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
    """The tracker's store (MLflow: the tracking URI); empty = its default store in the working directory
    (MLflow: a SQLite file)."""
    precision: str = "no"
    """One of ``PRECISIONS``."""
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
    """Every this many seconds the first worker of each node records the node's system metrics (CPU, memory,
    disk, network, GPU where present) into the job's run as ``system/node<k>/...``; 0 = off (the default)."""
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
    """How the network is run in training and validation: implementation, rays per training piece and per
    render chunk (``sray.model.runtime``), set field by field: ``--set runtime.chunk=4096``."""

    def __post_init__(self) -> None:
        """Reject settings of different sections that cannot train together."""
        check_sections(self)

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (JSON/YAML-safe; tuples become lists) with its ``format_version``."""
        return {VERSION_KEY: CONFIG_VERSION, **dataclasses.asdict(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_dict`, today's format only: OutdatedFormat (naming ``sray migrate``) for a config an
        earlier sray wrote, ValueError naming a field today's config does not have."""
        check_version(d, "train config")
        return from_plain(cls, {k: v for k, v in d.items() if k != VERSION_KEY}, "train config")

    def job_dir(self) -> Path:
        """Folder of this job's checkpoints and run state."""
        return Path(self.run.output_dir).resolve() / self.run.name


def check_sections(cfg: TrainConfig) -> None:
    """ValueError for settings of different sections that cannot train together: fp16 with a loss in pieces
    smaller than the batch (a piece's gradients are taken before the loss scaler scales them,
    ``sray.model.piecewise_loss``, so small ones could underflow), a 2D warm-up without the source-view
    head it trains, and a negative CPU budget."""
    if cfg.optim.cpu_seconds < 0:
        raise ValueError(f"train config: optim.cpu_seconds is {cfg.optim.cpu_seconds}; use 0 (steps only) or a "
                         "positive CPU-second budget")
    if cfg.optim.warmup_2d_steps < 0 or (cfg.optim.warmup_2d_steps > 0 and cfg.model.lambda_src_sem <= 0):
        raise ValueError(f"train config: optim.warmup_2d_steps is {cfg.optim.warmup_2d_steps}; it must be >= 0, and "
                         "a warm-up trains the source-view head, so it needs model.lambda_src_sem > 0 "
                         f"(is {cfg.model.lambda_src_sem}). Set model.lambda_src_sem=1 or optim.warmup_2d_steps=0.")
    if cfg.run.precision == "fp16" and 0 < cfg.runtime.train_piece < cfg.data.rays_per_batch:
        raise ValueError(f"train config: runtime.train_piece is {cfg.runtime.train_piece} (< data.rays_per_batch "
                         f"{cfg.data.rays_per_batch}) with run.precision=fp16; a piece's gradients are not "
                         "loss-scaled. "
                         "Set runtime.train_piece=0 (the whole batch on a GPU) or run.precision=bf16.")


def apply_override(cfg: TrainConfig, assignment: str) -> None:
    """Apply one ``section.field=value`` override in place, parsing the value as the field's type.

    Raises ValueError naming the unknown section or field and listing the valid ones, or a value the network
    cannot run with (the config keeps its previous value then).
    """

    def check() -> None:
        cfg.model.__post_init__()
        cfg.data.__post_init__()
        check_sections(cfg)

    set_field(cfg, assignment, "optim.lr=5e-4", check)


CONFIG_FILE = "config.json"
"""The job's full config, written into its folder (and logged as an artifact)."""


def load_job_config(output_dir: str, name: str) -> TrainConfig:
    """The saved config of an existing job (for ``--resume``); errors name the file and the fix (for a config an
    earlier sray wrote: ``sray migrate``)."""
    path = Path(output_dir) / name / CONFIG_FILE
    if not path.exists():
        raise FileNotFoundError(f"{path}: no job called {name!r} under {output_dir}; "
                                "check --name/--resume and the output folder (run.output_dir)")
    try:
        return TrainConfig.from_dict(json.loads(path.read_text()))
    except ValueError as e:
        raise type(e)(f"{path}: {e}") from None
