"""The fast render mode: model no more of a view than it needs. A documented approximation of the full render.

Three savings, each a setting of :class:`FastRender` (its accuracy cost is measured by
``sray bench speed-accuracy``, paired against the full render, never assumed):

* ``pixel_stride``: render every s-th pixel in each direction and upsample the rendered maps (logits,
  colours, depth, opacity) bilinearly to the pixels asked for (:func:`upsample_to`, applied by the whole-view
  renderer ``view_render.render_view``); label maps are piecewise constant, so most of a view is interior
  to a region;
* ``confidence``: a ray whose coarse pass already classifies it with probability >= ``confidence``
  keeps its coarse result; only the uncertain rays (boundaries, thin structures) get a fine pass. The probability
  is the softmax of the coarse logits divided by ``temperature`` (1 = as trained), which ``model.calibration``
  fits on validation rooms so that the confidence means the same on unfamiliar rooms;
* the fine pass evaluates only the resampled depths (``fine_samples="new"``), placed by inverse CDF
  where the coarse pass found density, instead of re-evaluating the coarse samples as well.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor

from .hierarchical import CoarseSampler, _render_pass, coarse_depths, per_ray_bounds
from .rendering import sample_pdf

FAST_KEYS = ("logits", "rgb", "depth", "opacity")
"""Per-pass outputs of a fast render (compositing weights and depths differ in size between rays)."""


@dataclass(frozen=True)
class FastRender:
    """Settings of the fast render mode (see the module docstring)."""

    pixel_stride: int = 8
    """Render every ``pixel_stride``-th pixel in each direction and upsample (1 = every pixel). The default
    (with ``confidence`` 0.9) cost -0.01 to +0.32 points of mIoU against the full render, paired, on every
    test view at 160x120 and +0.18 at 320x240, where it renders a view in about 1 s on 2 CPU cores
    (docs/benchmarks.md, "Speed against accuracy")."""
    confidence: float = 0.9
    """A ray whose coarse softmax maximum reaches this keeps its coarse result (> 1: every ray gets a fine pass)."""
    temperature: float = 1.0
    """The coarse logits are divided by this before the softmax of the confidence rule (1 = uncalibrated; > 1
    lowers the confidence, so more rays get a fine pass); fitted by ``calibration.fit_temperature``."""

    def __post_init__(self) -> None:
        """ValueError for a temperature that is not positive."""
        if not self.temperature > 0:
            raise ValueError(f"FastRender: temperature is {self.temperature}; it must be > 0 (1 = uncalibrated)")

    def fitted_pixel_stride(self, stride: int, hw: tuple[int, int]) -> int:
        """The pixel stride of a render of an (h, w) image scored every ``stride``-th pixel: ``pixel_stride``, or
        the largest smaller one whose ray grid still holds a ray in each direction (a small image or a large
        ``stride``: the grid's first pixel, ``stride * s // 2``, must lie inside the image)."""
        return max(1, min(self.pixel_stride, (2 * min(hw) - 1) // stride))  # stride * s // 2 < min(hw)

    def describe(self) -> str:
        """One phrase for protocol descriptors: ``fast (pixel stride 4, fine pass below 0.9 confidence, ...)``."""
        scaled = "" if self.temperature == 1.0 else f" at temperature {self.temperature:.3g}"
        return (f"fast (pixel stride {self.pixel_stride}, fine pass where the coarse confidence{scaled} < "
                f"{self.confidence:g}, resampled depths only)")


def needs_fine(coarse_logits: Tensor, confidence: float, temperature: float = 1.0) -> Tensor:
    """bool (R,): the rays whose coarse confidence, the softmax maximum of coarse_logits (R, L) / temperature,
    is below ``confidence`` (the fast rule)."""
    return torch.softmax(coarse_logits.float() / temperature, dim=-1).amax(-1) < confidence


def render_rays_fast(field: Callable[..., dict[str, Tensor]], origins: Tensor, dirs: Tensor,
                     near: Tensor | float, far: Tensor | float, n_coarse: int, n_fine: int,
                     confidence: float, coarse_sampler: CoarseSampler | None = None,
                     temperature: float = 1.0) -> dict[str, dict[str, Tensor]]:
    """Deterministic coarse pass on every ray, fine pass (resampled depths only) on the uncertain ones
    (:func:`needs_fine` at ``temperature``).

    field, origins (R, 3), dirs (R, 3), near, far, coarse_sampler as ``hierarchical.render_rays``. Returns
    ``{"coarse": pass, "fine": pass}`` with ``FAST_KEYS`` per pass; a confident ray's fine pass is
    its coarse pass.
    """
    n_rays = origins.shape[0]
    origins, dirs = origins.float(), dirs.float()
    near_r = per_ray_bounds(near, n_rays, origins, "near")
    far_r = per_ray_bounds(far, n_rays, origins, "far")
    ray_length = dirs.norm(dim=-1)
    z = coarse_depths(coarse_sampler, origins, dirs, near_r, far_r, n_coarse, stratified=False)
    coarse = _render_pass(field, "coarse", origins, dirs, z, near_r, far_r, ray_length)
    fine = {k: coarse[k].clone() for k in FAST_KEYS}
    unsure = needs_fine(coarse["logits"], confidence, temperature)  # (R,)
    idx = unsure.nonzero().squeeze(-1)
    if idx.numel() > 0:
        lo, hi = near_r[idx], far_r[idx]
        z_new = sample_pdf(z[idx], coarse["weights"][idx], lo, hi, n_fine, deterministic=True)
        out = _render_pass(field, "fine", origins[idx], dirs[idx], z_new, lo, hi, ray_length[idx])
        for k in FAST_KEYS:
            fine[k][idx] = out[k].to(fine[k].dtype)
    return {"coarse": {k: coarse[k] for k in FAST_KEYS}, "fine": fine}


def upsample_to(values: Tensor, grid_hw: tuple[int, int], stride: int, uv: Tensor) -> Tensor:
    """Bilinear values at pixels ``uv`` (P, 2) from a map rendered at every ``stride``-th pixel.

    values: (h', w', D) rendered at the pixel centres (stride // 2 + stride j, stride // 2 + stride i)
    (``view_render.strided_pixels``' grid); grid_hw = (h', w'). Returns (P, D); clamped at the border.
    """
    hh, ww = grid_hw
    fx = (uv[:, 0].float() - stride // 2) / stride
    fy = (uv[:, 1].float() - stride // 2) / stride
    grid = torch.stack([fx / max(ww - 1, 1) * 2 - 1, fy / max(hh - 1, 1) * 2 - 1], dim=-1)  # (P, 2)
    maps = values.float().permute(2, 0, 1)[None]  # (1, D, h', w')
    out = F.grid_sample(maps, grid[None, None], mode="bilinear", padding_mode="border", align_corners=True)
    return out[0, :, 0].T  # (P, D)
