"""The bare ``SRayModel`` of a training checkpoint: key migration and loading for eval, finetune and serving."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from torch import Tensor

from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.folders import load_checkpoint
from sray.platform.config.train_config import TrainConfig

LEGACY_PREFIX = "net."
"""Older checkpoints stored the training module's keys (``net.`` + the model's:
``sray.model.ray_batch.RayBatchLoss`` holds the network as ``net``)."""


def bare_model_keys(weights: dict[str, Tensor]) -> dict[str, Tensor]:
    """A checkpoint's model weights under the bare ``SRayModel`` keys (legacy ``net.`` keys stripped)."""
    if weights and all(k.startswith(LEGACY_PREFIX) for k in weights):
        return {k[len(LEGACY_PREFIX):]: v for k, v in weights.items()}
    return dict(weights)


def model_from_checkpoint(path: Any, map_location: str = "cpu") -> tuple[SRayModel, TrainConfig]:
    """The bare ``SRayModel`` (eval mode) and the job config stored in a training checkpoint folder."""
    state = load_checkpoint(Path(path), map_location)
    weights = state["model"]
    if any(k.endswith("attention.pos") for k in weights):
        raise ValueError(f"{path}: this checkpoint embeds sample ranks (an sray version before the depth position "
                         "signal); it cannot be loaded into the current model. Retrain it with `sray train`.")
    cfg = TrainConfig.from_dict(state["config"])
    net = SRayModel(cfg.model)
    net.load_state_dict(bare_model_keys(weights))
    return net.eval(), cfg
