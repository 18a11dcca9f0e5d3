"""What a training worker builds and checkpoints: model, optimiser, schedule, and their state."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import torch

from sray.model.ray_batch import RayBatchLoss
from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.folders import write_checkpoint
from sray.platform.config.train_config import OptimSettings, TrainConfig
from sray.platform.train.step import fused_adam

FIRST_COUNTERS: dict[str, int | float] = {"skipped_steps": 0, "cpu_seconds": 0.0, "wall_seconds": 0.0,
                                          "peak_memory_mb": 0.0}
"""The counters every checkpoint holds (at a job's start), summed or maxed across resumes; wall seconds NaN: unknown."""


def lr_lambda(opt: OptimSettings) -> Any:
    """Multiplier of the base lr at a step: linear warm-up, then exponential decay to lr_final over the rest."""
    ratio = opt.lr_final / opt.lr if opt.lr > 0 else 1.0  # a learning rate of 0 (a sweep's control arm) stays 0
    decay_steps = max(opt.steps - opt.warmup_steps, 1)

    def factor(step: float) -> float:
        if step < opt.warmup_steps:
            return (step + 1) / opt.warmup_steps
        return math.exp(math.log(ratio) * min(step - opt.warmup_steps, decay_steps) / decay_steps)

    return factor


def budget_lr_factor(opt: OptimSettings, step: int, cpu_seconds: float) -> float:
    """Base-lr multiplier at ``step`` after ``cpu_seconds`` of a CPU budget: warm-up by steps, decay by the further of
    the step and budget fractions."""
    return lr_lambda(opt)(step if step < opt.warmup_steps else max(step, cpu_seconds / opt.cpu_seconds * opt.steps))


def build_training(cfg: TrainConfig) -> tuple[RayBatchLoss, torch.optim.Optimizer, torch.optim.lr_scheduler.LambdaLR]:
    """Model (seeded from ``cfg.run.seed``: identical on every rank), Adam and its schedule."""
    torch.manual_seed(cfg.run.seed)
    model = RayBatchLoss(cfg.model, cfg.runtime)
    optimizer = fused_adam(list(model.parameters()), cfg.optim.lr)
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lr_lambda(cfg.optim))
    return model, optimizer, scheduler


def training_state(model: SRayModel, optimizer: torch.optim.Optimizer, scheduler: Any, scaler: Any, step: int,
                   cfg: TrainConfig, best_metric: float | None, counters: dict[str, int | float]) -> dict[str, Any]:
    """Full checkpoint state (weights_only-safe) of the bare model: the step is the NEXT step to run."""
    state: dict[str, Any] = {
        "model": model.state_dict(), "optimizer": optimizer.state_dict(), "scheduler": scheduler.state_dict(),
        "step": int(step), "config": cfg.to_dict(), "best_metric": None if best_metric is None else float(best_metric),
        "counters": {k: float(v) if isinstance(v, float) else int(v) for k, v in counters.items()}}
    if scaler is not None:
        state["scaler"] = scaler.state_dict()
    return state


def write_initial_checkpoint(cfg: TrainConfig, directory: Path) -> Path:
    """Write the step-0 checkpoint of ``build_training(cfg)`` (an untrained shared model) as folder ``directory``."""
    model, optimizer, scheduler = build_training(cfg)
    state = training_state(model.net, optimizer, scheduler, None, 0, cfg, None, dict(FIRST_COUNTERS))
    return write_checkpoint(state, directory, 0)


def restore_training(state: dict[str, Any], model: SRayModel, optimizer: torch.optim.Optimizer,
                     scheduler: Any) -> tuple[int, float | None, dict[str, int]]:
    """Load a :func:`training_state` (but its scaler); returns (next step, best metric, counters)."""
    model.load_state_dict(state["model"])
    optimizer.load_state_dict(state["optimizer"])
    scheduler.load_state_dict(state["scheduler"])
    return int(state["step"]), state["best_metric"], dict(state["counters"])
