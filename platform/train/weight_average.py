"""The exponential moving average of the trained weights (``optim.ema_decay``): the weights validation scores and
every reader of a checkpoint (evaluation, finetuning, serving) loads when it is on."""

from __future__ import annotations

from typing import Any

import torch
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn

from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.model_loading import AVERAGED_STEPS, AVERAGED_WEIGHTS


def weight_average(net: SRayModel, decay: float, device: torch.device | str) -> AveragedModel | None:
    """A copy of ``net`` on ``device`` whose parameters become, at each :meth:`AveragedModel.update_parameters`
    call, ``decay * average + (1 - decay) * weights`` (the first call copies the weights; buffers follow ``net``);
    None when ``decay`` is 0 (no average: the live weights are the model)."""
    if decay <= 0:
        return None
    return AveragedModel(net, device=device, multi_avg_fn=get_ema_multi_avg_fn(decay))


def averaged_state(average: AveragedModel) -> dict[str, Any]:
    """The checkpoint entries of an average: its bare ``SRayModel`` weights and how many steps it has taken in."""
    return {AVERAGED_WEIGHTS: average.module.state_dict(), AVERAGED_STEPS: int(average.n_averaged)}


def restore_average(state: dict[str, Any], average: AveragedModel) -> None:
    """Load a checkpoint's average (:func:`averaged_state`) into ``average``; a checkpoint without one (a job that
    turns the average on when resumed) leaves it to start from the weights at the next step."""
    if AVERAGED_WEIGHTS in state:
        average.module.load_state_dict(state[AVERAGED_WEIGHTS])
        average.n_averaged.fill_(int(state[AVERAGED_STEPS]))
