"""Reprojecting query-ray samples into the source views: the initial 3D contextual space M. ``sample_maps`` reads
feature pixel (j, i), centred on full-res pixel (4j, 4i), with ``grid_sample`` (``align_corners=True``, border
padding). A projection is valid at least ``min_depth`` in front of the source camera and inside [-0.5, W - 0.5] x
[-0.5, H - 0.5]; M at invalid projections is finite but meaningless and every consumer masks it, so it is never
zeroed (saving passes over the largest tensors)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from .encoder import FEATURE_STRIDE
from .source_gather import bilinear_taps, gather_bilinear, texel_table
from .source_set import SourceSet

_GRID_LIMIT = 2.0  # normalised grid coordinates are clamped to +-2 (outside +-1 is invalid anyway)


def project(points: Tensor, K: Tensor, w2c: Tensor, min_depth: float = 1e-6) -> tuple[Tensor, Tensor]:
    """Pinhole projection of world points (..., 3) into m views K (m, 3, 3), w2c (m, 4, 4): uv (m, ..., 2) pixels
    and depth (m, ...) camera z; uv is finite but meaningless closer than ``min_depth`` (mask with ``depth``).
    Runs in ``w2c``'s dtype with autocast off (bfloat16 moves pixels by several at 640 x 480)."""
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
    """Bilinear samples float32 (m, D, R, N) of maps (m, D, h, w), pixel (j, i) centred on full-res pixel (stride j,
    stride i), at full-res pixels uv (m, R, N, 2); float32 under autocast (bfloat16 grids are ~0.5 pixel off)."""
    h, w = maps.shape[-2:]
    scale = uv.new_tensor([2.0 / (stride * max(w - 1, 1)), 2.0 / (stride * max(h - 1, 1))])
    grid = (uv.float() * scale.float() - 1.0).clamp(-_GRID_LIMIT, _GRID_LIMIT)  # (m, R, N, 2)
    with torch.autocast(device_type=maps.device.type, enabled=False):
        return F.grid_sample(maps.float(), grid, mode="bilinear", padding_mode="border", align_corners=True)


def view_direction_difference(points: Tensor, query_dirs: Tensor, centres: Tensor, views_last: bool = False) -> Tensor:
    """IBRNet-style comparison of the query ray with each source ray through a sample: with unit q (query camera ->
    point) and s (source camera -> point), [(q - s) / |q - s|, q . s] (first part 0 where q = s). points (R, N, 3),
    query_dirs (R, 3) (any length), centres (m, 3) -> (m, R, N, 4), or (R, N, m, 4) with ``views_last``."""
    q = F.normalize(query_dirs, dim=-1)
    if views_last:
        q, s = q[:, None, None, :], points[:, :, None] - centres[None, None]  # (R, 1, 1, 3), (R, N, m, 3)
    else:
        q, s = q[None, :, None, :], points[None] - centres[:, None, None, :]  # (1, R, 1, 3), (m, R, N, 3)
    s = F.normalize(s, dim=-1)
    diff = q - s
    unit_diff = diff / diff.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    dot = (q * s).sum(-1, keepdim=True)
    return torch.cat([unit_diff, dot], dim=-1)


class ContextualSpace(nn.Module):
    """M (appendix L20-L22): reprojected features + an MLP of the view-direction difference."""

    def __init__(self, feat_dim: int, dir_hidden: int, min_depth: float) -> None:
        super().__init__()
        self.min_depth = min_depth
        self.dir_mlp = nn.Sequential(nn.Linear(4, dir_hidden), nn.ELU(), nn.Linear(dir_hidden, feat_dim))

    def forward(self, src: SourceSet, points: Tensor, query_dirs: Tensor, impl: str) -> dict[str, Tensor]:
        """points (R, N, 3) samples of the query rays, query_dirs (R, 3), ``impl`` one of ``runtime.IMPLS`` ->
        ``M`` (R, m, N, C), ``valid`` (R, m, N) bool, ``rgb`` (R, m, N, 3) source colours at the projections and
        ``dir`` (R, m, N, 4) (axes m and N swapped with ``impl="fast"``); meaningless where invalid."""
        uv, depth = project(points.float(), src.K.float(), src.w2c.float(), self.min_depth)
        if impl == "fast":  # gathered taps, every per-view tensor made in (R, N, m) order
            uv = uv.permute(1, 2, 0, 3)  # (R, N, m, 2): 2 channels are cheap to permute
            valid = valid_projection(uv, depth.permute(1, 2, 0), src.image_hw, self.min_depth)  # (R, N, m)
            idx, w = bilinear_taps(uv, 2, tuple(src.feats.shape[-2:]), FEATURE_STRIDE)  # (R, N, m, 4) each
            feats = gather_bilinear(texel_table(src.feats), idx, w)  # (R, N, m, C)
            idx, w = bilinear_taps(uv, 2, src.image_hw, 1)
            rgb = gather_bilinear(texel_table(src.rgb), idx, w)  # (R, N, m, 3)
            dirs = view_direction_difference(points.float(), query_dirs.float(), src.centres.float(), views_last=True)
            return {"M": feats + self.dir_mlp(dirs), "valid": valid, "rgb": rgb, "dir": dirs}
        valid = valid_projection(uv, depth, src.image_hw, self.min_depth)  # (m, R, N)
        feats = sample_maps(src.feats, uv, FEATURE_STRIDE)  # (m, C, R, N)
        rgb = sample_maps(src.rgb, uv, 1)  # (m, 3, R, N)
        dirs = view_direction_difference(points.float(), query_dirs.float(), src.centres.float())
        valid = valid.permute(1, 0, 2)  # (R, m, N)
        dirs = dirs.permute(1, 0, 2, 3)  # (R, m, N, 4)
        space = feats.permute(2, 0, 3, 1) + self.dir_mlp(dirs)  # (R, m, N, C)
        return {"M": space, "valid": valid, "rgb": rgb.permute(2, 0, 3, 1), "dir": dirs}
