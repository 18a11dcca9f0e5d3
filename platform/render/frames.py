"""One fly-through frame rendered whole: colour, labels, depth and confidence at every pixel.

The frame is rendered by the model's one whole-view renderer (``sray.model.view_render.render_view``, as
``sray eval``'s views are at stride 1), so a frame at a view's pose with that view's sources carries the same
labels and colours as ``sray eval``'s render of it; a frame also keeps the fine pass's depth and the per-pixel
confidence (the largest softmax probability of the rendered logits). In the fast mode the logits, colours
and depths of the strided grid are upsampled bilinearly, so a depth edge is blended over one grid cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from sray.data_tools.loader.sample_types import SceneQuery
from sray.model.fast_render import FastRender
from sray.model.view_render import RayRenderer, render_view


@dataclass(frozen=True)
class FrameRender:
    """What a frame shows, on CPU."""

    label: Tensor
    """int64 (H, W) argmax of the rendered logits."""
    rgb: Tensor
    """float32 (H, W, 3) colour in [0, 1]."""
    depth: Tensor
    """float32 (H, W) rendered z-depth in metres."""
    confidence: Tensor
    """float32 (H, W) largest softmax probability of the rendered logits, in [1/L, 1]."""


@torch.no_grad()
def render_frame(render: RayRenderer, sample: SceneQuery, hw: tuple[int, int], chunk: int, device: torch.device,
                 fast: FastRender | None = None) -> FrameRender:
    """Render every pixel of the ``hw`` = (H, W) image of ``sample``'s query camera with ``render`` (bound to
    ``sample``'s sources: ``SRayModel.ray_renderer``), in chunks of ``chunk`` rays (0: by device); with
    ``fast``, every ``fast.pixel_stride``-th pixel, upsampled (module doc)."""
    fine = render_view(render, sample.query.K, sample.query.c2w, hw, sample.near, sample.far, chunk, device,
                       fast=fast, passes=("fine",), keys=("logits", "rgb", "depth"))["fine"]
    logits = fine["logits"].cpu()  # (H, W, L)
    return FrameRender(label=logits.argmax(-1), rgb=fine["rgb"].cpu(), depth=fine["depth"].cpu(),
                       confidence=torch.softmax(logits, dim=-1).amax(-1))
