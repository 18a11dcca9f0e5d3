"""Reprojecting query-ray samples into the source views: the initial 3D contextual space M.

Pixel conventions (one place, used by ``sample_maps``):

* Full resolution: pixel (u, v) is centred at (u, v) in K's coordinates (the project-wide rule).
* Feature maps: the encoder centres feature pixel (j, i) on full-res pixel (4j, 4i) (see
  ``encoder.FEATURE_STRIDE``), so full-res (u, v) is feature coordinate (u / 4, v / 4).
* ``grid_sample`` is called with ``align_corners=True``, where normalised -1 and +1 are the centres
  of the first and last pixel: x = f / (w_map - 1) * 2 - 1 for map coordinate f. The source RGB is
  sampled the same way with stride 1. Border padding clamps the few valid projections that fall
  between the last feature centre and the image edge.

A projection is valid when the point lies at least ``min_depth`` in front of the source camera
and inside the image, u in [-0.5, W - 0.5] and v in [-0.5, H - 0.5]. Entries of M at invalid
projections are finite (border-clamped samples) but meaningless: every consumer masks them with
``valid`` (as attention keys, in the view weights, in the cross-view statistics and colour blend), so
they are never zeroed here, which saves full passes over the largest tensors.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from .encoder import FEATURE_STRIDE
from .source_gather import bilinear_taps, gather_bilinear, texel_table
from .source_set import SourceSet

_GRID_LIMIT = 2.0  # normalised grid coordinates are clamped to +-2 (outside +-1 is invalid anyway)


def project(points: Tensor, K: Tensor, w2c: Tensor, min_depth: float = 1e-6) -> tuple[Tensor, Tensor]:
    """Pinhole projection of shared points into m views.

    points: (..., 3) world coordinates; K: (m, 3, 3); w2c: (m, 4, 4).
    Returns uv (m, ..., 2) pixel coordinates and depth (m, ...) camera z. Points closer than
    ``min_depth`` (or behind the camera) get finite but meaningless uv; mask them with ``depth``.
    Runs in the dtype of ``w2c`` (float32 or float64) with autocast off: in bfloat16 the matmuls
    move projected pixels by up to several pixels at 640 x 480.
    """
    m = K.shape[0]
    lead = points.shape[:-1]
    with torch.autocast(device_type=points.device.type, enabled=False):
        flat = points.reshape(1, -1, 3).to(w2c.dtype)  # (1, P, 3)
        cam = flat @ w2c[:, :3, :3].transpose(1, 2) + w2c[:, None, :3, 3]  # (m, P, 3)
        depth = cam[..., 2]  # (m, P)
        pix = cam @ K.to(w2c.dtype).transpose(1, 2)  # (m, P, 3) = K x_cam
        uv = pix[..., :2] / depth.clamp_min(min_depth)[..., None]  # (m, P, 2)
    return uv.reshape(m, *lead, 2), depth.reshape(m, *lead)


def valid_projection(uv: Tensor, depth: Tensor, hw: tuple[int, int], min_depth: float) -> Tensor:
    """In front of the camera and inside the image: uv (m, ..., 2), depth (m, ...) -> bool (m, ...)."""
    h, w = hw
    u, v = uv[..., 0], uv[..., 1]
    inside = (u >= -0.5) & (u <= w - 0.5) & (v >= -0.5) & (v <= h - 0.5)
    return inside & (depth > min_depth)


def sample_maps(maps: Tensor, uv: Tensor, stride: int) -> Tensor:
    """Bilinear samples of per-view maps at full-res pixel coordinates.

    maps: (m, D, h, w) whose pixel (j, i) is centred on full-res pixel (stride j, stride i);
    uv: (m, R, N, 2) full-res pixel coordinates. Returns float32 (m, D, R, N): sampling runs in
    float32 even under autocast, since bfloat16 grid coordinates would be off by up to ~0.5 pixel.
    """
    h, w = maps.shape[-2:]
    scale = uv.new_tensor([2.0 / (stride * max(w - 1, 1)), 2.0 / (stride * max(h - 1, 1))])
    grid = (uv.float() * scale.float() - 1.0).clamp(-_GRID_LIMIT, _GRID_LIMIT)  # (m, R, N, 2)
    with torch.autocast(device_type=maps.device.type, enabled=False):
        return F.grid_sample(maps.float(), grid, mode="bilinear", padding_mode="border", align_corners=True)


def view_direction_difference(points: Tensor, query_dirs: Tensor, centres: Tensor) -> Tensor:
    """IBRNet-style 4-d comparison of the query ray with each source ray through a sample.

    points: (R, N, 3); query_dirs: (R, 3) (any length); centres: (m, 3) source camera centres.
    With unit vectors q (query camera -> point) and s (source camera -> point), returns
    (m, R, N, 4) = [(q - s) / |q - s|, q . s]; the first part is 0 where q = s.
    """
    q = F.normalize(query_dirs, dim=-1)[None, :, None, :]  # (1, R, 1, 3)
    s = F.normalize(points[None] - centres[:, None, None, :], dim=-1)  # (m, R, N, 3)
    diff = q - s
    unit_diff = diff / diff.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    dot = (q * s).sum(-1, keepdim=True)
    return torch.cat([unit_diff, dot], dim=-1)  # (m, R, N, 4)


def view_direction_difference_nm(points: Tensor, query_dirs: Tensor, centres: Tensor) -> Tensor:
    """``view_direction_difference`` computed in (R, N, m) order: (R, N, 3), (R, 3), (m, 3) -> (R, N, m, 4)."""
    q = F.normalize(query_dirs, dim=-1)[:, None, None, :]  # (R, 1, 1, 3)
    s = F.normalize(points[:, :, None] - centres[None, None], dim=-1)  # (R, N, m, 3)
    diff = q - s
    unit_diff = diff / diff.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    dot = (q * s).sum(-1, keepdim=True)
    return torch.cat([unit_diff, dot], dim=-1)  # (R, N, m, 4)


class ContextualSpace(nn.Module):
    """Builds M (appendix L20-L22): reprojected features plus an MLP of the view-direction difference.

    ``impl="reference"`` samples with ``grid_sample`` and returns (R, m, N, ...) tensors;
    ``impl="fast"`` gathers with ``source_gather`` and returns the same values in (R, N, m, ...)
    order (``fast_field``'s layout), within float32 rounding.
    """

    def __init__(self, feat_dim: int, dir_hidden: int, min_depth: float) -> None:
        super().__init__()
        self.min_depth = min_depth
        self.dir_mlp = nn.Sequential(nn.Linear(4, dir_hidden), nn.ELU(), nn.Linear(dir_hidden, feat_dim))

    def forward(self, src: SourceSet, points: Tensor, query_dirs: Tensor, impl: str) -> dict[str, Tensor]:
        """points: (R, N, 3) samples of the query rays; query_dirs: (R, 3); ``impl``: one of ``runtime.IMPLS``.

        Returns ``M`` (R, m, N, C), ``valid`` (R, m, N) bool, ``rgb`` (R, m, N, 3) source colours
        at the projections and ``dir`` (R, m, N, 4) (axes m and N swapped with ``impl="fast"``);
        entries at invalid projections are finite but meaningless (see the module docstring).
        """
        if impl == "fast":
            return self._fast(src, points, query_dirs)
        uv, depth = project(points.float(), src.K.float(), src.w2c.float(), self.min_depth)
        valid = valid_projection(uv, depth, src.image_hw, self.min_depth)  # (m, R, N)
        feats = sample_maps(src.feats, uv, FEATURE_STRIDE)  # (m, C, R, N)
        rgb = sample_maps(src.rgb, uv, 1)  # (m, 3, R, N)
        dirs = view_direction_difference(points.float(), query_dirs.float(), src.centres.float())
        valid = valid.permute(1, 0, 2)  # (R, m, N)
        dirs = dirs.permute(1, 0, 2, 3)  # (R, m, N, 4)
        space = feats.permute(2, 0, 3, 1) + self.dir_mlp(dirs)  # (R, m, N, C)
        return {"M": space, "valid": valid, "rgb": rgb.permute(2, 0, 3, 1), "dir": dirs}

    def _fast(self, src: SourceSet, points: Tensor, query_dirs: Tensor) -> dict[str, Tensor]:
        """``forward`` with gathered taps and every per-view tensor made in (R, N, m) order."""
        uv, depth = project(points.float(), src.K.float(), src.w2c.float(), self.min_depth)
        uv = uv.permute(1, 2, 0, 3)  # (R, N, m, 2): 2 channels are cheap to permute
        valid = valid_projection(uv, depth.permute(1, 2, 0), src.image_hw, self.min_depth)  # (R, N, m)
        idx, w = bilinear_taps(uv, 2, tuple(src.feats.shape[-2:]), FEATURE_STRIDE)  # (R, N, m, 4) each
        feats = gather_bilinear(texel_table(src.feats), idx, w)  # (R, N, m, C)
        idx, w = bilinear_taps(uv, 2, src.image_hw, 1)
        rgb = gather_bilinear(texel_table(src.rgb), idx, w)  # (R, N, m, 3)
        dirs = view_direction_difference_nm(points.float(), query_dirs.float(), src.centres.float())
        return {"M": feats + self.dir_mlp(dirs), "valid": valid, "rgb": rgb, "dir": dirs}
