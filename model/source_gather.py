"""Bilinear sampling of per-view maps as a weighted gather, the fast path of ``reprojection.sample_maps`` (same
conventions): ``F.embedding_bag(mode="sum")`` over 4 texels of a (m * h * w, D) table, whose backward is one sorted
accumulation instead of ``grid_sample``'s element-wise CPU scatter (docs/benchmarks/profile.md)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor


def bilinear_taps(uv: Tensor, view_dim: int, hw_map: tuple[int, int], stride: int) -> tuple[Tensor, Tensor]:
    """Texel rows idx (..., 4) int64 of the (m * h * w) table and bilinear weights (..., 4) float32 (summing to 1,
    border-clamped) of the 4 taps of each sample: uv (..., 2) full-res pixels whose dimension ``view_dim`` is the
    source view (e.g. (R, m, N, 2), view_dim 1); hw_map: the map's (h, w)."""
    h, w = hw_map
    m = uv.shape[view_dim]
    shape = [1] * (uv.ndim - 1)
    shape[view_dim] = m
    with torch.no_grad():
        f = uv.detach().float() / stride
        fx = f[..., 0].clamp(0.0, w - 1.0)
        fy = f[..., 1].clamp(0.0, h - 1.0)
        x0 = fx.floor().clamp(max=max(w - 2, 0))
        y0 = fy.floor().clamp(max=max(h - 2, 0))
        ax, ay = fx - x0, fy - y0  # (m, ...) in [0, 1]
        x0i, y0i = x0.long(), y0.long()
        x1i, y1i = (x0i + 1).clamp(max=w - 1), (y0i + 1).clamp(max=h - 1)
        base = (torch.arange(m, device=uv.device) * (h * w)).view(shape)
        r0, r1 = base + y0i * w, base + y1i * w
        idx = torch.stack([r0 + x0i, r0 + x1i, r1 + x0i, r1 + x1i], dim=-1)
        weights = torch.stack([(1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay], dim=-1)
    return idx, weights


def texel_table(maps: Tensor) -> Tensor:
    """Per-view maps (m, D, h, w) as one float32 texel table (m * h * w, D), row = (view, y, x)."""
    m, d, h, w = maps.shape
    return maps.float().permute(0, 2, 3, 1).reshape(m * h * w, d)


def gather_bilinear(table: Tensor, idx: Tensor, weights: Tensor) -> Tensor:
    """Weighted sum of 4 rows of table (T, D) per sample (idx, weights (..., 4)) -> (..., D) float32."""
    lead = idx.shape[:-1]
    with torch.autocast(device_type=table.device.type, enabled=False):
        out = F.embedding_bag(idx.reshape(-1, 4), table, per_sample_weights=weights.reshape(-1, 4).to(table.dtype),
                              mode="sum")
    return out.view(*lead, table.shape[-1])
