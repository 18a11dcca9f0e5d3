"""One fly-through frame rendered whole: colour, labels, depth and confidence at every pixel.

The rays, chunks and fast-mode upsampling are those of evaluation (``platform/eval/view_scoring.py``
``render_view`` at stride 1), so a frame at a view's pose with that view's sources carries the same labels
and colours as ``sray eval``'s render of it; a frame also keeps the fine pass's depth and the per-pixel
confidence (the largest softmax probability of the rendered logits). In the fast mode the logits, colours
and depths of the strided grid are upsampled bilinearly, so a depth edge is blended over one grid cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from sray.data_tools.loader.sample_types import SceneQuery
from sray.model.fast_render import FastRender, upsample_to
from sray.platform.common.model_input import ray_batch
from sray.platform.eval.view_scoring import Renderer, fitted_pixel_stride, render_in_chunks, strided_pixels


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
def render_frame(render: Renderer, sample: SceneQuery, hw: tuple[int, int], chunk: int, device: torch.device,
                 fast: FastRender | None = None) -> FrameRender:
    """Render every pixel of the ``hw`` = (H, W) image of ``sample``'s query camera with ``render`` (bound to
    ``sample``'s sources: ``view_scoring.sray_renderer``), in chunks of ``chunk`` rays (0: by device); with
    ``fast``, every ``fast.pixel_stride``-th pixel, upsampled (module doc)."""
    h, w = hw
    uv, _, _ = strided_pixels(h, w, 1)
    stride = fitted_pixel_stride(fast.pixel_stride, 1, hw) if fast is not None else 1
    uv_r, hr, wr = strided_pixels(h, w, stride)
    origins, dirs, near, far = ray_batch(sample, uv_r).query.to(device).rays()       # (R, 3), (R, 3), (R,), (R,)
    pred_logits, pred_rgb, pred_depth = render_in_chunks(render, origins, dirs, near, far, chunk, with_depth=True)
    if stride != 1:
        pred_logits = upsample_to(pred_logits.reshape(hr, wr, -1), (hr, wr), stride, uv)
        pred_rgb = upsample_to(pred_rgb.reshape(hr, wr, 3), (hr, wr), stride, uv)
        pred_depth = upsample_to(pred_depth.reshape(hr, wr, 1), (hr, wr), stride, uv)
    return FrameRender(label=pred_logits.argmax(-1).reshape(h, w), rgb=pred_rgb.reshape(h, w, 3),
                       depth=pred_depth.reshape(h, w),
                       confidence=torch.softmax(pred_logits, dim=-1).amax(-1).reshape(h, w))
