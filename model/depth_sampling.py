"""RGB-D mode (``SRayConfig.inputs = "rgbd"``): the source views' depth places the coarse samples.

The rule, in two steps (the query view's own depth is never an input; only the m source depth maps
of the :class:`~sray.model.source_set.SourceSet` are read):

1. **Where the sources saw a surface on the ray** (:func:`source_surface_depth`). P probes at the bin
   centres of P equal bins of [near, far] (deterministic, also in training) are projected into every
   source view. At a probe that projects inside view i, in front of it, onto a pixel of known depth
   (nearest pixel, so depth edges are never blended), ``s = z_probe - D_i`` is the probe's camera
   depth minus the depth that view measured there: negative in the free space the view saw, zero on
   its surface. View i's estimate is the first sign change ``s_k < 0 <= s_{k+1}`` between two such
   neighbouring probes with both ``|s|`` at most the probe spacing along the ray (``dt |d|``) plus
   ``depth_band``; a larger jump is the edge of something in front of the ray in that view (the ray
   passes into its shadow), not a surface. The crossing is interpolated linearly between the two
   probes. The ray's surface depth is the lower median of the views' estimates; NaN where no view
   has one (nothing known, or every source grazing or occluded).
2. **Samples around it** (:func:`surface_samples`). Of the n coarse samples, ``round(fraction * n)``
   go into the band ``[t - depth_band, t + depth_band]`` clipped to [near, far] and the others
   cover the rest of [near, far] (the two pieces outside the band, as one stretch), each set in equal
   bins: stratified in training, bin centres in evaluation. So exactly that share lies in the band
   and the rest of the ray keeps samples when the sources are wrong. A ray without a surface depth
   gets the rgb mode's samples, bit for bit (``rendering.sample_uniform`` with the same random draws).

The fine pass is unchanged: inverse CDF of the coarse weights (``rendering.sample_pdf``), whose bins
follow any sorted coarse samples.
"""

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
    """Ray parameter (z-depth) of the first surface the source depths show on each ray (rule 1 above).

    src: with ``depth`` (m, H, W) metres, 0 = unknown; origins, dirs (R, 3); near, far (R,).
    Returns float32 (R,), NaN on rays without an estimate.
    """
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
