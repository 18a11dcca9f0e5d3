"""RGB-D mode (``SRayConfig.inputs = "rgbd"``): the source views' depth places the coarse samples (the query view's
depth is never an input). The rule (docs/model.md, "RGB-D mode"): :func:`source_surface_depth` finds the first
surface the source depths show on each ray, :func:`surface_samples` puts ``depth_fraction`` of the coarse samples
in a band around it and the rest over [near, far]."""

from __future__ import annotations

import torch
from torch import Tensor

from .reprojection import project, valid_projection
from .source_set import SourceSet


def _nearest_depth(depth: Tensor, uv: Tensor) -> Tensor:
    """Source depth at the nearest pixel: depth (m, H, W), uv (m, R, P, 2) -> (m, R, P) (clamped to the image)."""
    m, h, w = depth.shape
    u = uv[..., 0].round().clamp(0, w - 1).long()
    v = uv[..., 1].round().clamp(0, h - 1).long()
    flat = (v * w + u).reshape(m, -1)  # (m, R*P)
    return depth.reshape(m, h * w).gather(1, flat).reshape(u.shape)


@torch.no_grad()
def source_surface_depth(src: SourceSet, origins: Tensor, dirs: Tensor, near: Tensor, far: Tensor,
                         n_probe: int, band: float, min_depth: float) -> Tensor:
    """Ray parameter (z-depth) of the first surface the source depths (``src.depth`` (m, H, W) metres, 0 =
    unknown) show on each ray (rule 1): origins, dirs (R, 3), near, far (R,) -> float32 (R,), NaN: no estimate."""
    if src.depth is None:
        raise ValueError("sray.model.depth_sampling: the source set has no depth; encode the sources with "
                         "`src_depth` (m, H, W) for inputs='rgbd'.")
    if n_probe < 2:
        raise ValueError(f"sray.model.depth_sampling: n_probe must be >= 2, got {n_probe}.")
    step = ((far - near) / n_probe).float()  # (R,) probe spacing in t
    t = near[:, None].float() + step[:, None] * (torch.arange(n_probe, device=near.device) + 0.5)  # (R, P)
    points = origins.float()[:, None, :] + t[..., None] * dirs.float()[:, None, :]  # (R, P, 3)
    uv, z_cam = project(points, src.K.float(), src.w2c.float(), min_depth)  # (m, R, P, 2), (m, R, P)
    seen = _nearest_depth(src.depth.float(), uv)  # (m, R, P)
    valid = valid_projection(uv, z_cam, src.image_hw, min_depth) & (seen > 0)
    s = z_cam - seen  # (m, R, P) signed: < 0 in the free space the view saw
    tol = (step * dirs.float().norm(dim=-1) + band)[None, :, None]  # (1, R, 1)
    s0, s1 = s[..., :-1], s[..., 1:]  # (m, R, P-1) each
    crossing = valid[..., :-1] & valid[..., 1:] & (s0 < 0) & (s1 >= 0) & (-s0 <= tol) & (s1 <= tol)
    first = crossing.to(torch.uint8).argmax(-1, keepdim=True)  # (m, R, 1) first crossing (0 if none)
    a, b = s0.gather(-1, first)[..., 0], s1.gather(-1, first)[..., 0]  # (m, R)
    t0 = t[:, :-1].expand_as(s0).gather(-1, first)[..., 0]  # (m, R)
    estimate = t0 + step[None] * (-a / (b - a).clamp_min(1e-12))  # (m, R) linear interpolation
    estimate = torch.where(crossing.any(-1), estimate, torch.full_like(estimate, float("nan")))
    return estimate.nanmedian(dim=0).values  # (R,) lower median over the views with an estimate


def surface_samples(near: Tensor, far: Tensor, surface: Tensor, n: int, fraction: float, band: float,
                    stratified: bool, generator: torch.Generator | None = None) -> Tensor:
    """Sorted coarse depths (R, n) in [near, far], ``round(fraction * n)`` of them in the band around
    ``surface`` (rule 2 above). near, far, surface: (R,); surface NaN = no estimate (uniform samples)."""
    n_rays, device = near.shape[0], near.device
    n_band = int(round(fraction * n))
    offset: Tensor | float = torch.rand(n_rays, n, generator=generator, device=device) if stratified else 0.5
    steps = torch.arange(n, device=device, dtype=near.dtype)  # (n,)
    uniform = near[:, None] + (far - near)[:, None] * ((steps + offset) / n)  # (R, n): sample_uniform's formula
    if n_band == 0:
        return uniform
    known = ~surface.isnan()  # (R,)
    centre = torch.where(known, surface, near)
    lo = torch.minimum(torch.maximum(centre - band, near), far)  # (R,)
    hi = torch.minimum(torch.maximum(centre + band, near), far)
    pos = (steps + offset).expand(n_rays, n)  # (R, n) bin index + offset in the bin
    inside = lo[:, None] + (hi - lo)[:, None] * pos[:, :n_band] / n_band  # (R, n_band)
    parts = [inside]
    if n > n_band:
        before = (lo - near)[:, None]  # (R, 1) length of [near, lo]
        rest = (far - near - (hi - lo))[:, None] * (pos[:, n_band:] - n_band) / (n - n_band)  # (R, n - n_band)
        parts.append(torch.where(rest < before, near[:, None] + rest, hi[:, None] + (rest - before)))
    guided = torch.sort(torch.cat(parts, dim=-1), dim=-1).values  # (R, n)
    return torch.where(known[:, None], guided, uniform)
