"""Typed configuration of a finetune fleet (``sray finetune-fleet``): budgets, method settings, scheduling; ``--set``
overrides any field. Fields whose default is None inherit the shared checkpoint's training value."""

from __future__ import annotations

from dataclasses import dataclass, field
from operator import attrgetter
from typing import Any

from sray.platform.config.held_out_render import HeldOutRender
from sray.platform.config.overrides import apply_settings, set_field

PRECISIONS = ("no", "bf16", "fp16")
"""fp32, bfloat16 autocast (CPU and CUDA), float16 autocast with loss scaling (CUDA only)."""
DEFAULT_ADAPT = ("encoder.merge2", "encoder.head", "coarse", "fine")
"""S-Ray modules a finetune trains and stores by default: the image encoder's last two layers and both per-sample
networks (about 3% of the model's bytes). Of the seven module sets measured on unseen rooms, adapting the image
features is what transferred, and this set held most of the accuracy of the larger ones at a fraction of their
artifact bytes (stored in jobs/studies/results/finetune-adapt); a wider set is one ``--set`` away."""


@dataclass
class FinetuneSettings:
    """Budget, early stopping and optimisation of one scene's finetune (both methods)."""

    max_steps: int = 300
    """Most optimiser steps a scene may use."""
    max_seconds: float = 0.0
    """Training wall-clock budget per scene in seconds (evaluation not counted); 0 = none."""
    max_cpu_seconds: float = 0.0
    """Training CPU seconds per scene (``step_budget``; other jobs on the cores do not inflate it); 0 = none."""
    eval_every: int = 25
    """Held-out evaluation cadence in steps (also after step 0, the zero-shot model)."""
    patience: int = 3
    """Stop after this many evaluations in a row without an improvement of the held-out mIoU."""
    min_delta: float = 0.002
    """An evaluation improves only if its held-out mIoU beats the best so far by more than this."""
    lr: float = 1e-3
    """Adam learning rate of the adapted S-Ray parameters (constant; the paper's initial rate)."""
    grad_clip: float = 1.0
    """Global gradient-norm clipping of the trained parameters (0 = off)."""
    max_nonfinite_in_row: int = 20
    """A non-finite loss or gradient skips the step; this many in a row fail the scene."""
    rays_per_batch: int | None = None
    """Rays per step; None = the checkpoint's ``data.rays_per_batch``."""
    n_source: int | None = None
    """Source views per training sample; None = the checkpoint's ``model.n_source``."""
    top_k: int | None = None
    """Training sources are drawn from this many ranked neighbours; None = the checkpoint's ``data.top_k`` (capped)."""
    held_out: HeldOutRender = field(default_factory=lambda: HeldOutRender(stride=2, fast_stride=1))
    """Held-out scoring: 8 fixed sources, every 2nd pixel, fast render; ``--set finetune.held_out.render=full``."""
    eval_chunk: int = 0
    """Rays per forward pass when rendering held-out views; 0 = by device (``sray.model.ray_chunks``)."""
    precision: str = "no"
    """One of ``PRECISIONS``; fp16 needs ``gpus_per_task > 0``."""
    adapt: tuple[str, ...] = DEFAULT_ADAPT
    """S-Ray module paths (prefixes of ``SRayModel.state_dict()`` keys) trained and stored per scene."""
    seed: int = 0
    """Seed of ray sampling, data order and Semantic-NeRF's initial weights."""


@dataclass
class SemanticNeRFSettings:
    """Semantic-NeRF from scratch, the per-scene baseline (method ``semantic-nerf``)."""

    lr: float = 5e-4
    """Adam learning rate (Semantic-NeRF: 5e-4)."""
    depth: int = 8
    """Trunk layers (paper: 8)."""
    width: int = 256
    """Trunk width (paper: 256)."""
    skip_layer: int | None = 5
    """Trunk layer the encoded position re-enters (NeRF: 5); must be below ``depth``; None = no skip."""
    pos_freqs: int = 10
    """Positional-encoding frequencies of positions."""
    dir_freqs: int = 4
    """Positional-encoding frequencies of directions."""
    n_coarse: int | None = None
    """Coarse samples per ray; None = the S-Ray checkpoint's (same sampling budget)."""
    n_fine: int | None = None
    """Fine samples per ray; None = the S-Ray checkpoint's."""


@dataclass
class TransferSettings:
    """2D label transfer (method ``2d-transfer``): the pretrained segmenter it starts from and its finetune."""

    segmenter: str = ""
    """Folder of the pretrained 2D segmenter (``sray bench segmenter --out``); required by ``2d-transfer``."""
    lr: float = 1e-3
    """Adam learning rate of the whole segmenter (constant; the rate ``sray bench segmenter`` pretrains with)."""
    images_per_step: int = 4
    """Labelled images per finetune step: a sample's source views, from its ``finetune.top_k`` neighbours."""
    tolerance: float = 0.05
    """Relative depth agreement of the forward splatting's occlusion test (``label_transfer``)."""


@dataclass
class FleetConfig:
    """Everything a fleet needs besides the checkpoint, the shards, the scenes and the methods."""

    finetune: FinetuneSettings = field(default_factory=FinetuneSettings)
    """Per-scene budgets and optimisation."""
    nerf: SemanticNeRFSettings = field(default_factory=SemanticNeRFSettings)
    """The Semantic-NeRF baseline's network and learning rate."""
    transfer: TransferSettings = field(default_factory=TransferSettings)
    """The 2D label-transfer method's segmenter and finetune."""
    max_parallel: int = 2
    """Most scene tasks in flight at once."""
    cpus_per_task: float = 1.0
    """CPUs Ray reserves per scene task (fractions allowed)."""
    gpus_per_task: float = 0.0
    """GPUs per scene task (fractions let several finetunes share a GPU; 0 = CPU)."""
    retries: int = 2
    """Re-runs of a scene task after a failure (worker crash or error) before it is reported."""
    retry_backoff_s: float = 5.0
    """Wait before the first re-run; doubled for each further one."""
    experiment: str = "sray-fleet"
    """Experiment of the parent fleet run and its child runs."""
    tracker: str = "mlflow"
    """Tracker of those runs, by registry name (``sray.platform.tracking.registry``)."""
    address: str = ""
    """Ray cluster address; empty = start Ray locally in-process."""

    def __post_init__(self) -> None:
        """Reject settings a fleet cannot run with, naming the field and the fix."""
        check_fleet_config(self)


POSITIVE = ("finetune.max_steps", "finetune.eval_every", "finetune.patience", "finetune.max_nonfinite_in_row",
            "max_parallel", "nerf.depth", "nerf.width", "transfer.images_per_step", "finetune.rays_per_batch",
            "finetune.n_source", "finetune.top_k", "nerf.n_coarse", "nerf.n_fine")
"""Fleet fields that must be positive integers where set (None: inherited from the checkpoint)."""
NON_NEGATIVE = ("finetune.eval_chunk", "finetune.max_seconds", "finetune.max_cpu_seconds", "finetune.min_delta",
                "finetune.lr", "finetune.grad_clip", "nerf.lr", "transfer.lr", "cpus_per_task", "gpus_per_task",
                "retries", "retry_backoff_s")
"""Fleet fields that must be >= 0."""


def check_fleet_config(cfg: FleetConfig) -> None:
    """ValueError naming the first field that is out of range."""
    ft = cfg.finetune
    for path in POSITIVE:
        if (value := attrgetter(path)(cfg)) is not None and int(value) < 1:
            raise ValueError(f"fleet config: {path} is {value}; it must be a positive integer")
    for path in NON_NEGATIVE:
        if (value := attrgetter(path)(cfg)) < 0:
            raise ValueError(f"fleet config: {path} is {value}; it must be >= 0")
    if cfg.transfer.tolerance <= 0:
        raise ValueError(f"fleet config: transfer.tolerance is {cfg.transfer.tolerance}; it must be > 0 (a relative "
                         "depth agreement, e.g. 0.05)")
    if cfg.cpus_per_task == 0 and cfg.gpus_per_task == 0:
        raise ValueError("fleet config: cpus_per_task and gpus_per_task are both 0; a task needs some CPU or GPU")
    ft.held_out.check(lambda field: f"fleet config: finetune.held_out.{field}")
    if ft.precision not in PRECISIONS:
        raise ValueError(f"fleet config: finetune.precision is {ft.precision!r}; use one of {PRECISIONS}")
    if ft.precision == "fp16" and cfg.gpus_per_task == 0:
        raise ValueError("fleet config: finetune.precision fp16 needs CUDA (set --gpus-per-task > 0); "
                         "on CPU use bf16 or no")
    if cfg.nerf.skip_layer is not None and not 0 < cfg.nerf.skip_layer < cfg.nerf.depth:
        raise ValueError(f"fleet config: nerf.skip_layer is {cfg.nerf.skip_layer}; it must lie in 1..nerf.depth - 1 "
                         f"({cfg.nerf.depth - 1}) or be none")
    if not ft.adapt:
        raise ValueError("fleet config: finetune.adapt is empty; name at least one S-Ray module, e.g. "
                         "fine.classifier")


def apply_fleet_override(cfg: FleetConfig, assignment: str) -> None:
    """Apply one ``[section.]field=value`` override in place (``overrides.set_field``): ValueError names an unknown
    section or field, or a value out of range (the config keeps its previous value then)."""
    set_field(cfg, assignment, "finetune.patience=5", lambda: check_fleet_config(cfg))


def build_fleet_config(flags: dict[str, Any], assignments: list[str]) -> FleetConfig:
    """A command's FleetConfig: the defaults, then its flags (``path -> value``), then its ``--set`` assignments."""
    cfg = FleetConfig()
    apply_settings(cfg, flags, assignments, apply_fleet_override)
    return cfg
