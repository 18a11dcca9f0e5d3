"""What ``sray eval`` scores: any method's pretrained model as one record, :class:`EvalModel`, made by the method's
``eval_model`` builder (S-Ray: :func:`checkpoint_model`; ``2d-transfer``: :func:`segmenter_model`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from sray.data_tools.loader.sample_types import EvalSample
from sray.model.fast_render import FastRender
from sray.model.runtime import Runtime
from sray.model.view_render import RayRenderer
from sray.platform.checkpoints.folders import read_meta
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.eval.segmenter import load_segmenter, transfer_renderer
from sray.platform.eval.view_scoring import sray_renderer


@dataclass(frozen=True)
class EvalModel:
    """A pretrained model ready to score unseen scenes with no per-scene step."""

    renderer: Callable[[EvalSample], RayRenderer]
    """The ray renderer of one evaluation sample (bound to its fixed sources)."""
    n_classes: int
    """Classes L it predicts (the scenes' label space must have as many)."""
    ignore_id: int
    inputs: str
    """Source-view inputs of its protocol (``rgb`` or ``rgbd``, ``EvalProtocol.inputs``)."""
    fast: FastRender | None
    """The fast render mode its renderer uses (None: the full render)."""
    chunk: int
    """Rays per forward pass (0: by device)."""
    device: torch.device
    step: int
    """Step the tracked metrics are logged at (the checkpoint's training step; 0 for a model without one)."""
    record: dict[str, Any]
    """What it is, first in ``metrics.json`` and the run's params (e.g. ``checkpoint``, ``checkpoint_step``)."""
    name: str
    """Short name inside the tracked run's name (``eval-<name>-<time>``)."""
    tags: dict[str, str]
    """Run tags naming it (e.g. ``sray.checkpoint``)."""
    subject: str
    """What predicts, in error messages ("the checkpoint's model")."""


def torch_device(device: str | None) -> torch.device:
    """``device`` (a torch device name), or CUDA when available, else the CPU."""
    return torch.device(device or ("cuda" if torch.cuda.is_available() else "cpu"))


def with_source_inputs(net: nn.Module, inputs: str) -> nn.Module:
    """``net`` (S-Ray) reading the source ``inputs`` with the same parameters (docs/model.md "RGB-D mode")."""
    net.cfg = dataclasses.replace(net.cfg, inputs=inputs)
    return net


def checkpoint_model(checkpoint: Path, device: str | None = None, fast: FastRender | None = None,
                     runtime: Runtime = Runtime(), inputs: str = "") -> EvalModel:
    """The S-Ray model of a training checkpoint folder, rendering with ``fast`` (None: the full render) and
    ``runtime`` on ``device`` (default: CUDA if available), reading the source ``inputs`` (empty: the checkpoint's)."""
    checkpoint = Path(checkpoint).resolve()
    net, cfg = model_from_checkpoint(checkpoint)
    if inputs:
        with_source_inputs(net, inputs)
    step = int(read_meta(checkpoint if checkpoint.is_dir() else checkpoint.parent)["step"])
    where = torch_device(device)
    net = net.to(where).eval()
    job = f"{checkpoint.parent.parent.name}-" if checkpoint.parent.name == "checkpoints" else ""
    record = {"checkpoint": str(checkpoint), "checkpoint_step": step} | ({"inputs": inputs} if inputs else {})
    return EvalModel(renderer=lambda s: sray_renderer(net, s, where, fast, runtime), n_classes=cfg.model.n_classes,
                     ignore_id=cfg.model.ignore_id, inputs=net.cfg.inputs, fast=fast, chunk=runtime.chunk,
                     device=where, step=step, record=record,
                     name=f"{job}{checkpoint.name}", tags={"sray.checkpoint": str(checkpoint)},
                     subject="the checkpoint's model")


def segmenter_model(folder: Path, device: str | None = None, tolerance: float = 0.05) -> EvalModel:
    """``2d-transfer`` with the segmenter saved in ``folder`` (``transfer_renderer``, occlusion test ``tolerance``)."""
    folder = Path(folder).resolve()
    segmenter, record = load_segmenter(folder)
    where = torch_device(device)
    segmenter = segmenter.to(where).eval()
    return EvalModel(renderer=lambda s: transfer_renderer(segmenter, s, tolerance, where),
                     n_classes=segmenter.cfg.n_classes, ignore_id=segmenter.cfg.ignore_id, inputs="rgbd", fast=None,
                     chunk=0, device=where, step=0,
                     record={"method": "2d-transfer", "segmenter": {"folder": str(folder), **record.training},
                             "tolerance": tolerance},
                     name=f"2d-transfer-{folder.name}",
                     tags={"sray.method": "2d-transfer", "sray.segmenter": str(folder)}, subject="the segmenter")
