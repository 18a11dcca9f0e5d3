"""Geometry-aware net (appendix table) on the initial M (R, m, N, C): L1-L4 per-view features gated by
sigmoid(Linear(C, 1)); L5-L7 mean and variance over the valid views (float32); L8 MLP 2C -> 32 -> 16; L9 attention
along the ray; L10-L11 MLP -> softplus density (the appendix lists ReLU; softplus has no dead units at the start),
0 where no view sees the sample. Colour (the paper leaves it open): IBRNet-style blending of the source colours by
a softmax over the valid views of a score MLP (C + 4 -> 16 -> 1) of gated feature and view-direction difference."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from .config import SRayConfig
from .cra import AttentionBlock


def masked_mean_var(x: Tensor, valid: Tensor, dim: int) -> tuple[Tensor, Tensor]:
    """Float32 mean and (biased) variance over ``dim`` of the valid entries of x (..., K, ..., D), which is ZERO
    where ``valid`` (same shape without D) is False: the (K - n) zeros' (K - n) mean^2 is subtracted from the
    two-pass sum of squared deviations. Rows without a valid entry give 0."""
    with torch.autocast(device_type=x.device.type, enabled=False):
        xf = x.float()
        n_valid = valid.float().sum(dim, keepdim=True)[..., None]
        n_zeros = x.shape[dim] - n_valid
        n = n_valid.clamp_min(1.0)
        mean = xf.sum(dim, keepdim=True) / n
        sq = (xf - mean).square().sum(dim, keepdim=True) - n_zeros * mean.square()
        var = sq.clamp_min(0.0) / n
    return mean.squeeze(dim), var.squeeze(dim)


def masked_softmax(logits: Tensor, valid: Tensor, dim: int) -> Tensor:
    """Float32 softmax over the valid entries of ``dim``; 0 at invalid entries and in rows without any."""
    with torch.autocast(device_type=logits.device.type, enabled=False):
        any_valid = valid.any(dim, keepdim=True)
        masked = logits.float().masked_fill(~valid, float("-inf"))
        masked = torch.where(any_valid, masked, torch.zeros_like(masked))  # no all -inf rows
        return torch.softmax(masked, dim=dim) * valid.float()


def blend_colours(score: Tensor, valid: Tensor, src_rgb: Tensor, view_dim: int) -> Tensor:
    """Source colours (..., 3) blended by the softmax of ``score`` over the valid views: (R, N, 3) float32."""
    return (masked_softmax(score, valid, dim=view_dim)[..., None] * src_rgb.float()).sum(dim=view_dim)


class GeometryNet(nn.Module):
    """M (R, m, N, C) -> density (R, N) and blended colour (R, N, 3)."""

    def __init__(self, cfg: SRayConfig) -> None:
        super().__init__()
        c = cfg.feat_dim
        g1, g2 = cfg.geo_hidden
        self.feature = nn.Sequential(nn.Linear(c, c), nn.ELU())  # L1
        self.gate = nn.Linear(c, 1)  # L2 (sigmoid: L3)
        self.fuse = nn.Sequential(nn.Linear(2 * c, g1), nn.ELU(), nn.Linear(g1, g2), nn.ELU())  # L8
        self.ray_attention = AttentionBlock(g2, cfg.n_heads)  # L9
        self.density = nn.Sequential(nn.Linear(g2, g2), nn.ELU(), nn.Linear(g2, 1))  # L10, L11
        self.colour_score = nn.Sequential(nn.Linear(c + 4, 16), nn.ELU(), nn.Linear(16, 1))

    def gated_density(self, space: Tensor, valid: Tensor, view_dim: int) -> tuple[Tensor, Tensor]:
        """Gated per-view features (0 where invalid) and density sigma (R, N) float32 (L1-L11) of M whose views are
        on ``view_dim`` (1 for (R, m, N, C), 2 for the fast path's (R, N, m, C))."""
        keep = valid[..., None].to(space.dtype)
        gated = self.feature(space) * (torch.sigmoid(self.gate(space)) * keep)
        mean, var = masked_mean_var(gated, valid, dim=view_dim)  # (R, N, C) each
        seen = valid.any(dim=view_dim)  # (R, N)
        g = self.ray_attention(self.fuse(torch.cat([mean, var], dim=-1)), seen)  # (R, N, 16)
        return gated, F.softplus(self.density(g).squeeze(-1).float()) * seen.float()

    def forward(self, space: Tensor, valid: Tensor, dirs: Tensor, src_rgb: Tensor) -> tuple[Tensor, Tensor]:
        """space: (R, m, N, C) (ignored where invalid); valid: (R, m, N); dirs: (R, m, N, 4);
        src_rgb: (R, m, N, 3) source colours at the projections. Returns sigma (R, N), rgb (R, N, 3)."""
        gated, sigma = self.gated_density(space, valid, 1)
        score = self.colour_score(torch.cat([gated, dirs.to(gated.dtype)], dim=-1)).squeeze(-1)  # (R, m, N)
        return sigma, blend_colours(score, valid, src_rgb, 1)
