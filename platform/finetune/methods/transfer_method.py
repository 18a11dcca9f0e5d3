"""2D label transfer (``2d-transfer``): segmenter labels of the source views carried by their depth to the query."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

from sray.platform.finetune.methods.method import ChartStyle, EvalRequest, Method, SceneContext, SceneSetup

if TYPE_CHECKING:
    from torch import nn

    from sray.platform.config.fleet_config import FleetConfig
    from sray.platform.eval.eval_model import EvalModel

NAME = "2d-transfer"


def build(ctx: SceneContext) -> SceneSetup:
    """A ``TransferLearner`` on ``transfer.segmenter`` (ValueError unless of the checkpoint's classes)."""
    from sray.platform.eval.segmenter import load_segmenter
    from sray.platform.finetune.learners import TransferLearner

    cfg, ft = ctx.cfg, ctx.cfg.finetune
    segmenter, _ = load_segmenter(Path(cfg.transfer.segmenter))
    if segmenter.cfg.n_classes != ctx.n_classes:
        raise ValueError(f"fleet config: transfer.segmenter {cfg.transfer.segmenter} predicts "
                         f"{segmenter.cfg.n_classes} classes, the checkpoint and scene {ctx.scene!r} have "
                         f"{ctx.n_classes}; train the segmenter on the checkpoint's label space")
    learner = TransferLearner(segmenter, cfg.transfer.lr, ft.grad_clip, ft.precision, ctx.device,
                              ft.max_nonfinite_in_row, cfg.transfer.tolerance)
    top_k = ft.top_k or min(ctx.train_cfg.data.top_k, ctx.stored_neighbours)
    n_images = min(cfg.transfer.images_per_step, top_k)
    return SceneSetup(learner=learner, n_source=n_images, top_k=top_k, source_labels=True)


def load(artifact: Path, base_checkpoint: Path) -> nn.Module:
    """The scene's finetuned segmenter rebuilt from its artifact (the shared checkpoint is not needed)."""
    from sray.platform.finetune.scene_artifacts import load_segmenter_artifact

    return load_segmenter_artifact(artifact)


def eval_model(request: EvalRequest) -> EvalModel:
    """The pretrained segmenter of ``--segmenter`` with the source-depth transfer (it reads no render flag)."""
    from sray.platform.eval.eval_model import segmenter_model

    if request.segmenter is None:
        raise ValueError(f"method {NAME} needs a 2D segmenter: pass --segmenter FOLDER (written by `sray bench "
                         "segmenter --data SHARDS --cpu-seconds S --out FOLDER`)")
    return segmenter_model(request.segmenter, request.device)


def checked_config(cfg: FleetConfig) -> FleetConfig:
    """``cfg`` with ``transfer.segmenter`` made absolute (tasks may run elsewhere) once it is set and loads."""
    from sray.platform.eval.segmenter import load_segmenter

    if not cfg.transfer.segmenter:
        raise ValueError(f"fleet config: transfer.segmenter is empty; method {NAME} starts from a pretrained 2D "
                         "segmenter: pass --segmenter FOLDER (or --set transfer.segmenter=FOLDER), a folder written "
                         "by `sray bench segmenter`")
    folder = Path(cfg.transfer.segmenter).resolve()
    load_segmenter(folder)
    return dataclasses.replace(cfg, transfer=dataclasses.replace(cfg.transfer, segmenter=str(folder)))


METHOD = Method(
    name=NAME, summary="2D segmenter labels carried by the source depth (RGB-D), segmenter finetuned", build=build,
    artifact_file="segmenter.safetensors", load=load, uses_sources=True,
    style=ChartStyle(label="2d-transfer finetune", color="#e08a1e", marker="D"),
    zero_shot=ChartStyle(label="2d-transfer zero-shot (pretrained segmenter)", color="#f2c27b", marker="X"),
    eval_model=eval_model, eval_reads=("segmenter",), inputs="rgbd", checked_config=checked_config)
