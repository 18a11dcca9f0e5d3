"""S-Ray given the source views' depth (``sray-rgbd``): the shared checkpoint in RGB-D mode (docs/model.md "RGB-D
mode": the source depth places the coarse samples; the parameters are the RGB mode's), finetuned per scene as
``sray`` is. An RGB-D method, registered as ``sray``'s depth twin (``Method.given_depth_of``): wherever a method
that reads the source depth is compared (``2d-transfer``), S-Ray given that same depth stands beside it
(:func:`sray.platform.finetune.methods.registry.with_depth_twins`).

Its artifact is ``sray``'s (the adapted tensors plus the shared checkpoint's checksum); loading it puts the model in
RGB-D mode again. Its step-0 score is the shared model's zero-shot score given the depth (``sray eval --method
sray-rgbd --checkpoint C``).
"""

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
"""The method's registry name."""
INPUTS = "rgbd"
"""What it reads of the source views (``model.inputs``)."""


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
    artifact_file=sray_method.METHOD.artifact_file, load=load,
    style=ChartStyle(label="S-Ray finetune, with source depth", color="#9467bd", marker="P"), uses_sources=True,
    zero_shot=ChartStyle(label="S-Ray zero-shot, with source depth", color="#8c564b", marker="v"),
    eval_model=eval_model, eval_reads=("checkpoint", "fast"), inputs=INPUTS, given_depth_of=sray_method.NAME,
    clips=True)
"""S-Ray's RGB-D per-scene method."""
