"""S-Ray finetune: the shared model with only ``finetune.adapt`` trained per scene (step 0: zero-shot)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from sray.platform.finetune.methods.method import ChartStyle, EvalRequest, Method, SceneContext, SceneSetup

if TYPE_CHECKING:
    from torch import nn

    from sray.platform.eval.eval_model import EvalModel


NAME = "sray"


def build(ctx: SceneContext) -> SceneSetup:
    """An ``SRayLearner`` on the shared model, its samples' sources as the checkpoint's (or ``finetune.*``)."""
    from sray.platform.finetune.learners import SRayLearner

    ft = ctx.cfg.finetune
    learner = SRayLearner(ctx.base, ctx.base_sha256, ft.adapt, ft.lr, ft.grad_clip, ft.precision, ctx.device,
                          ft.max_nonfinite_in_row, ft.held_out.fast())
    n_source = ft.n_source or ctx.train_cfg.model.n_source
    top_k = ft.top_k or min(ctx.train_cfg.data.top_k, ctx.stored_neighbours)
    return SceneSetup(learner=learner, n_source=n_source, top_k=top_k)


def load(artifact: Path, base_checkpoint: Path) -> nn.Module:
    """The finetuned model: the shared checkpoint plus the artifact (refused if made from another one)."""
    from sray.platform.finetune.scene_artifacts import load_scene_model

    return load_scene_model(base_checkpoint, artifact)


def eval_model(request: EvalRequest) -> EvalModel:
    """The shared model of ``--checkpoint`` (zero-shot), rendered as ``--render`` says, with the request's inputs."""
    from sray.platform.eval.eval_model import checkpoint_model

    if request.checkpoint is None:
        raise ValueError("method sray scores a checkpoint: pass --checkpoint FOLDER (a step_XXXXXXXXX folder written "
                         "by `sray train`)")
    return checkpoint_model(request.checkpoint, request.device, request.fast, inputs=request.inputs)


METHOD = Method(
    name=NAME, summary="finetune the shared S-Ray model", build=build, artifact_file="sray_delta.safetensors",
    load=load, style=ChartStyle(label="S-Ray finetune", color="#1f6fb4", marker="o"), uses_sources=True, clips=True,
    zero_shot=ChartStyle(label="S-Ray zero-shot (step 0, no per-scene steps)", color="#6b9fd1", marker="*"),
    eval_model=eval_model, eval_reads=("checkpoint", "fast", "inputs"))
