"""The bare ``SRayModel`` of a training checkpoint, for eval, finetune and serving."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.folders import load_checkpoint
from sray.platform.config.train_config import TrainConfig


def model_from_checkpoint(path: Any, map_location: str = "cpu") -> tuple[SRayModel, TrainConfig]:
    """The bare ``SRayModel`` (eval mode) and job config of a checkpoint folder; ValueError: older (sray migrate)."""
    state = load_checkpoint(Path(path), map_location)
    try:
        cfg = TrainConfig.from_dict(state["config"])
    except ValueError as e:
        raise type(e)(f"{path}: {e}") from None
    net = SRayModel(cfg.model)
    net.load_state_dict(state["model"])
    return net.eval(), cfg
