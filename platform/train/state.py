"""What a training worker builds and checkpoints: model, optimiser, schedule, and their state."""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import Tensor

from sray.model.ray_batch import RayBatchModel
from sray.model.semantic_ray import SRayModel
from sray.platform.config.train_config import OptimSettings, TrainConfig
from sray.platform.train.step import fused_adam


def lr_lambda(opt: OptimSettings) -> Any:
    """Multiplier of the base lr at a step: linear warm-up, then exponential decay to lr_final."""
    ratio = opt.lr_final / opt.lr
    decay_steps = max(opt.steps - opt.warmup_steps, 1)

    def factor(step: int) -> float:
        if step < opt.warmup_steps:
            return (step + 1) / opt.warmup_steps
        return math.exp(math.log(ratio) * min(step - opt.warmup_steps, decay_steps) / decay_steps)

    return factor


def build_training(cfg: TrainConfig) -> tuple[RayBatchModel, torch.optim.Optimizer, torch.optim.lr_scheduler.LambdaLR]:
    """Model (seeded from ``cfg.run.seed``, identical on every rank), Adam and its schedule."""
    torch.manual_seed(cfg.run.seed)
    model = RayBatchModel(cfg.model)
    optimizer = fused_adam(list(model.parameters()), cfg.optim.lr)
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lr_lambda(cfg.optim))
    return model, optimizer, scheduler


LEGACY_PREFIX = "net."
"""Checkpoints written before 2026-11-23 stored the training module's keys (``net.`` + the model's:
``sray.model.ray_batch.RayBatchModel`` holds the network as ``net``)."""


def bare_model_keys(weights: dict[str, Tensor]) -> dict[str, Tensor]:
    """A checkpoint's model weights under the bare ``SRayModel`` keys (legacy ``net.`` keys stripped)."""
    if weights and all(k.startswith(LEGACY_PREFIX) for k in weights):
        return {k[len(LEGACY_PREFIX):]: v for k, v in weights.items()}
    return dict(weights)


def training_state(model: SRayModel, optimizer: torch.optim.Optimizer, scheduler: Any, scaler: Any,
                   step: int, cfg: TrainConfig, best_metric: float | None, counters: dict[str, int]) -> dict[str, Any]:
    """Full checkpoint state (weights_only-safe) of the bare model: the step is the NEXT step to run."""
    state: dict[str, Any] = {
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "scheduler": scheduler.state_dict(),
        "step": int(step),
        "config": cfg.to_dict(),
        "best_metric": None if best_metric is None else float(best_metric),
        "counters": {k: int(v) for k, v in counters.items()},
    }
    if scaler is not None:
        state["scaler"] = scaler.state_dict()
    return state


def restore_training(state: dict[str, Any], model: SRayModel, optimizer: torch.optim.Optimizer,
                     scheduler: Any, scaler: Any) -> tuple[int, float | None, dict[str, int]]:
    """Load a :func:`training_state` dict (legacy keys too) into live objects; returns (next step, best
    metric, counters). ``model`` is the bare network whose parameters the optimizer holds, in order."""
    model.load_state_dict(bare_model_keys(state["model"]))
    optimizer.load_state_dict(state["optimizer"])
    scheduler.load_state_dict(state["scheduler"])
    if scaler is not None and "scaler" in state:
        scaler.load_state_dict(state["scaler"])
    return int(state["step"]), state.get("best_metric"), dict(state.get("counters", {}))


def model_from_checkpoint(path: Any, map_location: str = "cpu") -> tuple[SRayModel, TrainConfig]:
    """The bare ``SRayModel`` (eval mode) and the job config stored in a training checkpoint folder."""
    from pathlib import Path

    from sray.platform.train.checkpoints import load_checkpoint

    state = load_checkpoint(Path(path), map_location)
    if any(k.endswith("attention.pos") for k in state["model"]):
        raise ValueError(f"{path}: this checkpoint embeds sample ranks (sray before the depth position signal "
                         "of issue 8); it cannot be loaded into the current model. Retrain it with `sray train`.")
    cfg = TrainConfig.from_dict(state["config"])
    net = SRayModel(cfg.model)
    net.load_state_dict(bare_model_keys(state["model"]))
    return net.eval(), cfg
