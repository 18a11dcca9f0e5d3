"""What a training worker builds and checkpoints: model, optimiser, schedule, and their state."""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import Tensor, nn

from sray.model.config import SRayConfig
from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.model_loading import bare_model_keys
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
