"""Camera rays of query pixels (OpenCV axes; pixel (u, v) is centred at (u, v) in K's coordinates)."""

from __future__ import annotations

import torch
from torch import Tensor


def pixel_rays(K: Tensor, c2w: Tensor, uv: Tensor) -> tuple[Tensor, Tensor]:
    """Rays through pixels: K (3, 3), c2w (4, 4), uv (R, 2) -> origins, dirs (R, 3); ``dirs = R_c2w K^-1 [u, v, 1]``
    has camera-z 1 (NOT unit length), so t of ``o + t d`` is the z-depth. In ``c2w``'s dtype with autocast off (in
    bfloat16 a principal point of 159.5 rounds to 160)."""
    if K.shape != (3, 3) or c2w.shape != (4, 4) or uv.ndim != 2 or uv.shape[-1] != 2:
        raise ValueError(f"sray.model.rays.pixel_rays: expected K (3, 3), c2w (4, 4), uv (R, 2); got "
                         f"{tuple(K.shape)}, {tuple(c2w.shape)}, {tuple(uv.shape)}.")
    dtype = c2w.dtype
    with torch.autocast(device_type=c2w.device.type, enabled=False):
        ones = torch.ones_like(uv[:, :1], dtype=dtype)
        pix = torch.cat([uv.to(dtype), ones], dim=-1)  # (R, 3) homogeneous pixels
        cam = torch.linalg.solve(K.to(dtype), pix.T).T  # (R, 3) = K^-1 [u, v, 1], z = 1
        dirs = cam @ c2w[:3, :3].T  # (R, 3) rotated into the world
    origins = c2w[:3, 3].expand_as(dirs)  # (R, 3)
    return origins, dirs


def image_pixels(h: int, w: int, device: torch.device | str | None = None) -> Tensor:
    """All pixel centres of an h x w image in row-major order: (h * w, 2) float32 (u, v)."""
    v, u = torch.meshgrid(torch.arange(h, device=device, dtype=torch.float32),
                          torch.arange(w, device=device, dtype=torch.float32), indexing="ij")
    return torch.stack([u.reshape(-1), v.reshape(-1)], dim=-1)  # (h*w, 2)
