"""The fast render mode, an approximation of the full render (cost measured by ``sray bench speed-accuracy``,
docs/benchmarks/speed-accuracy.md): rays every ``pixel_stride``-th pixel, maps upsampled bilinearly
(:func:`upsample_to`, applied by ``view_render``); a fine pass (resampled depths only) just for rays whose coarse
softmax (logits / ``temperature``, ``model.calibration``) is below ``confidence``."""

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
    """Settings of the fast render mode (module doc)."""

    pixel_stride: int = 8
    """Render every ``pixel_stride``-th pixel in each direction and upsample (1 = every pixel); the default's cost
    against the full render is in docs/benchmarks/speed-accuracy.md."""
    confidence: float = 0.9
    """A ray whose coarse softmax maximum reaches this keeps its coarse result (> 1: every ray gets a fine pass)."""
    temperature: float = 1.0
    """The coarse logits are divided by this before the confidence softmax (1 = uncalibrated; > 1 sends more rays
    to the fine pass); fitted by ``calibration.fit_temperature``."""

    def __post_init__(self) -> None:
        """ValueError for a temperature that is not positive."""
        if not self.temperature > 0:
            raise ValueError(f"FastRender: temperature is {self.temperature}; it must be > 0 (1 = uncalibrated)")

    def fitted_pixel_stride(self, stride: int, hw: tuple[int, int]) -> int:
        """``pixel_stride``, shrunk until the ray grid of an image scored every ``stride``-th pixel fits."""
        return max(1, min(self.pixel_stride, (2 * min(hw) - 1) // stride))  # stride * s // 2 < min(hw)

    def describe(self) -> str:
        """One phrase for protocol descriptors: ``fast (pixel stride 4, fine pass where ..., ...)``."""
        scaled = "" if self.temperature == 1.0 else f" at temperature {self.temperature:.3g}"
        return (f"fast (pixel stride {self.pixel_stride}, fine pass where the coarse confidence{scaled} < "
                f"{self.confidence:g}, resampled depths only)")


def needs_fine(coarse_logits: Tensor, confidence: float, temperature: float = 1.0) -> Tensor:
    """bool (R,): rays whose softmax maximum of coarse_logits (R, L) / temperature is below ``confidence``."""
    return torch.softmax(coarse_logits.float() / temperature, dim=-1).amax(-1) < confidence


def render_rays_fast(field: Callable[..., dict[str, Tensor]], origins: Tensor, dirs: Tensor,
                     near: Tensor | float, far: Tensor | float, n_coarse: int, n_fine: int,
                     confidence: float, coarse_sampler: CoarseSampler | None = None,
                     temperature: float = 1.0) -> dict[str, dict[str, Tensor]]:
    """Deterministic coarse pass on every ray, fine pass (resampled depths only) where :func:`needs_fine`; arguments
    as ``hierarchical.render_rays``. Returns both passes' ``FAST_KEYS`` (a confident ray's fine pass is its coarse)."""
    n_rays = origins.shape[0]
    origins, dirs = origins.float(), dirs.float()
    near_r = per_ray_bounds(near, n_rays, origins, "near")
    far_r = per_ray_bounds(far, n_rays, origins, "far")
    ray_length = dirs.norm(dim=-1)
    z = coarse_depths(coarse_sampler, origins, dirs, near_r, far_r, n_coarse, stratified=False)
    coarse = _render_pass(field, "coarse", origins, dirs, z, near_r, far_r, ray_length)
    fine = {k: coarse[k].clone() for k in FAST_KEYS}
    idx = needs_fine(coarse["logits"], confidence, temperature).nonzero().squeeze(-1)  # uncertain rays
    if idx.numel() > 0:
        lo, hi = near_r[idx], far_r[idx]
        z_new = sample_pdf(z[idx], coarse["weights"][idx], lo, hi, n_fine, deterministic=True)
        out = _render_pass(field, "fine", origins[idx], dirs[idx], z_new, lo, hi, ray_length[idx])
        for k in FAST_KEYS:
            fine[k][idx] = out[k].to(fine[k].dtype)
    return {"coarse": {k: coarse[k] for k in FAST_KEYS}, "fine": fine}


def upsample_to(values: Tensor, grid_hw: tuple[int, int], stride: int, uv: Tensor) -> Tensor:
    """Bilinear values (P, D) at pixels uv (P, 2), clamped at the border, from values (h', w', D) rendered at
    every ``stride``-th pixel (``view_render.strided_pixels``' grid: centres stride // 2 + stride j)."""
    hh, ww = grid_hw
    fx = (uv[:, 0].float() - stride // 2) / stride
    fy = (uv[:, 1].float() - stride // 2) / stride
    grid = torch.stack([fx / max(ww - 1, 1) * 2 - 1, fy / max(hh - 1, 1) * 2 - 1], dim=-1)  # (P, 2)
    maps = values.float().permute(2, 0, 1)[None]  # (1, D, h', w')
    out = F.grid_sample(maps, grid[None, None], mode="bilinear", padding_mode="border", align_corners=True)
    return out[0, :, 0].T  # (P, D)
