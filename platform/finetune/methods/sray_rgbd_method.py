"""S-Ray given the source depth (``sray-rgbd``, docs/model.md "RGB-D mode"): ``sray``'s depth twin."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

from sray.platform.finetune.methods import sray_method
from sray.platform.finetune.methods.method import ChartStyle, EvalRequest, Method, SceneContext, SceneSetup

if TYPE_CHECKING:
    from torch import nn

    from sray.platform.eval.eval_model import EvalModel

NAME = "sray-rgbd"
INPUTS = "rgbd"


def build(ctx: SceneContext) -> SceneSetup:
    """``sray``'s learner on the shared model in RGB-D mode (the training samples carry the source depth)."""
    from sray.platform.eval.eval_model import with_source_inputs

    return sray_method.build(dataclasses.replace(ctx, base=with_source_inputs(ctx.base, INPUTS)))


def load(artifact: Path, base_checkpoint: Path) -> nn.Module:
    """The finetuned model (``sray``'s loader) in RGB-D mode."""
    from sray.platform.eval.eval_model import with_source_inputs

    return with_source_inputs(sray_method.load(artifact, base_checkpoint), INPUTS)


def eval_model(request: EvalRequest) -> EvalModel:
    """The shared model of ``--checkpoint`` given the source depth, rendered as ``--render`` says."""
    return sray_method.eval_model(dataclasses.replace(request, inputs=INPUTS))


METHOD = Method(
    name=NAME, summary="finetune the shared S-Ray model given the source depth (RGB-D)", build=build,
    artifact_file=sray_method.METHOD.artifact_file, load=load, uses_sources=True, clips=True,
    style=ChartStyle(label="S-Ray finetune, with source depth", color="#9467bd", marker="P"),
    zero_shot=ChartStyle(label="S-Ray zero-shot, with source depth", color="#8c564b", marker="v"),
    eval_model=eval_model, eval_reads=("checkpoint", "fast"), inputs=INPUTS, given_depth_of=sray_method.NAME)
