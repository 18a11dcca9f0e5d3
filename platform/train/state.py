"""What a training worker builds and checkpoints: model, optimiser, schedule, and their state."""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import Tensor, nn

from sray.model.config import SRayConfig
from sray.model.semantic_ray import SRayModel
from sray.platform.config.train_config import OptimSettings, TrainConfig
from sray.platform.train.step import fused_adam


class RayBatchModel(nn.Module):
    """One ``forward`` = encode the source views + render a ray batch.

    DDP synchronises gradients only for work done inside ``forward``, so the training step goes
    through this wrapper instead of calling ``encode`` / ``render_rays`` on the bare model.
    """

    def __init__(self, cfg: SRayConfig) -> None:
        """Build the wrapped S-Ray network (no device work here)."""
        super().__init__()
        self.net = SRayModel(cfg)

    def forward(self, src_rgb: Tensor, src_K: Tensor, src_c2w: Tensor, origins: Tensor, dirs: Tensor,
                near: Tensor, far: Tensor) -> dict[str, dict[str, Tensor]]:
        """src_rgb (m,3,H,W), src_K (m,3,3), src_c2w (m,4,4), origins/dirs (R,3), near/far (R,).

        Samples are stratified in training mode and deterministic in eval mode.
        """
        src = self.net.encode(src_rgb, src_K, src_c2w)
        return self.net.render_rays(src, origins, dirs, near, far, stratified=self.training)


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
"""Checkpoints written before 2026-11-23 stored the training wrapper's keys (``net.`` + the model's)."""


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
