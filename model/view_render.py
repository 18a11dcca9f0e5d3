"""The one whole-view renderer of ``sray.model``: a query camera's pixels -> rays -> chunked render -> maps.
:func:`render_view` renders every ``stride``-th pixel (exact pixel centres, so ground truth is read without
resampling), ``chunk`` rays at a time without grad, float32 outputs on the device, colours clamped to [0, 1]. The
fast mode (``fast_render.FastRender``) owns its pixel stride and the bilinear upsampling to the asked pixels; its ray
renderer is ``SRayModel.ray_renderer(src, fast)``."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from .fast_render import FastRender, upsample_to
from .hierarchical import IMAGE_KEYS, PASSES
from .ray_chunks import render_chunk_rays
from .rays import pixel_rays

RayRenderer = Callable[[Tensor, Tensor, Tensor, Tensor], dict[str, dict[str, Tensor]]]
"""``render(origins (R, 3), dirs (R, 3), near (R,), far (R,)) -> {"coarse": pass, "fine": pass}``, deterministic,
with the passes and keys the caller asks for."""


def strided_pixels(h: int, w: int, stride: int) -> tuple[Tensor, int, int]:
    """(uv (h' * w', 2), h', w'): every ``stride``-th pixel centre of an (h, w) image, row-major."""
    vs = torch.arange(stride // 2, h, stride, dtype=torch.float32)
    us = torch.arange(stride // 2, w, stride, dtype=torch.float32)
    v, u = torch.meshgrid(vs, us, indexing="ij")
    return torch.stack([u.reshape(-1), v.reshape(-1)], dim=-1), len(vs), len(us)


def _render_chunks(render: RayRenderer, origins: Tensor, dirs: Tensor, near: Tensor, far: Tensor, chunk: int,
                   passes: tuple[str, ...], keys: tuple[str, ...]) -> dict[str, dict[str, Tensor]]:
    """``keys`` of ``passes`` for R rays, ``chunk`` rays at a time: (R, ...) float32 each."""
    parts: dict[str, dict[str, list[Tensor]]] = {p: {k: [] for k in keys} for p in passes}
    for start in range(0, origins.shape[0], chunk):
        sl = slice(start, start + chunk)
        out = render(origins[sl], dirs[sl], near[sl], far[sl])
        for p, per_pass in parts.items():
            for k, items in per_pass.items():
                items.append(out[p][k].float())
    return {p: {k: torch.cat(v) for k, v in per_pass.items()} for p, per_pass in parts.items()}


@torch.no_grad()
def render_view(render: RayRenderer, K: Tensor, c2w: Tensor, hw: tuple[int, int], near: float, far: float,
                chunk: int, device: torch.device, stride: int = 1, fast: FastRender | None = None,
                passes: tuple[str, ...] = PASSES, keys: tuple[str, ...] = IMAGE_KEYS) -> dict[str, dict[str, Tensor]]:
    """Render every ``stride``-th pixel of the (H, W) = ``hw`` image of the query camera K (3, 3), c2w (4, 4) with
    z-depth bounds ``near``, ``far``, ``chunk`` rays per pass (0: by device). Returns ``{pass: {"logits": (h', w', L),
    "rgb": (h', w', 3), "depth": (h', w'), "opacity": (h', w')}}`` (``keys`` of ``passes``), float32 on ``device``."""
    if stride < 1:
        raise ValueError(f"sray.model.view_render.render_view: stride must be >= 1, got {stride}.")
    h, w = hw
    uv, hh, ww = strided_pixels(h, w, stride)
    ray_stride = stride * (fast.fitted_pixel_stride(stride, hw) if fast is not None else 1)
    uv_r, hr, wr = strided_pixels(h, w, ray_stride)
    origins, dirs = pixel_rays(K.to(device).float(), c2w.to(device).float(), uv_r.to(device))  # (R, 3) each
    near_r = torch.full((len(uv_r),), float(near), dtype=torch.float32, device=device)  # (R,)
    far_r = torch.full((len(uv_r),), float(far), dtype=torch.float32, device=device)  # (R,)
    out = _render_chunks(render, origins, dirs, near_r, far_r, render_chunk_rays(chunk, device), passes, keys)
    uv = uv.to(device)

    def on_grid(values: Tensor) -> Tensor:
        """(R, ...) per ray -> (h', w', ...) at the asked pixels (upsampled when the rays are sparser)."""
        if ray_stride != stride:
            return upsample_to(values.reshape(hr, wr, -1), (hr, wr), ray_stride, uv).reshape(hh, ww, *values.shape[1:])
        return values.reshape(hh, ww, *values.shape[1:])

    for per_pass in out.values():
        if "rgb" in per_pass:
            per_pass["rgb"] = per_pass["rgb"].clamp(0, 1)
    return {p: {k: on_grid(v) for k, v in per_pass.items()} for p, per_pass in out.items()}
