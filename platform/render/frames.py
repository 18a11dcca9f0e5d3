"""One frame rendered whole by ``model.view_render.render_view``, as ``sray eval``'s views at stride 1; in the fast
mode logits, colours and depths are upsampled bilinearly (a depth edge blends over one grid cell)."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from sray.data_tools.loader.sample_types import SceneQuery
from sray.model.fast_render import FastRender
from sray.model.view_render import RayRenderer, render_view


@dataclass(frozen=True)
class FrameRender:
    """A frame on CPU: ``label`` int64 (H, W) argmax of the logits, ``rgb`` float32 (H, W, 3) in [0, 1], ``depth``
    float32 (H, W) fine-pass z-depth (m), ``confidence`` float32 (H, W) largest softmax probability, in [1/L, 1]."""

    label: Tensor
    rgb: Tensor
    depth: Tensor
    confidence: Tensor


@torch.no_grad()
def render_frame(render: RayRenderer, sample: SceneQuery, hw: tuple[int, int], chunk: int, device: torch.device,
                 fast: FastRender | None = None) -> FrameRender:
    """Render the (H, W) = ``hw`` image of ``sample``'s query camera with ``render`` (``SRayModel.ray_renderer`` on
    its sources) in ``chunk``-ray chunks (0: by device); ``fast``: every ``fast.pixel_stride``-th pixel, upsampled."""
    fine = render_view(render, sample.query.K, sample.query.c2w, hw, sample.near, sample.far, chunk, device,
                       fast=fast, passes=("fine",), keys=("logits", "rgb", "depth"))["fine"]
    logits = fine["logits"].cpu()  # (H, W, L)
    return FrameRender(label=logits.argmax(-1), rgb=fine["rgb"].cpu(), depth=fine["depth"].cpu(),
                       confidence=torch.softmax(logits, dim=-1).amax(-1))
