"""Geometry-aware net (appendix table): density per sample, plus a colour head for the photometric loss.

Density path, on the initial contextual space M (R, m, N, C) as the table states:

* L1-L4: per-view features ELU(Linear(C, C)) gated by sigmoid(Linear(C, 1));
* L5-L7: mean and variance over the VALID views (float32), concatenated (2C);
* L8: MLP 2C -> 32 -> 16 (ELU);
* L9: 4-head attention along the ray over its N samples (an ``AttentionBlock`` without
  feed-forward; samples no view sees are masked as keys);
* L10-L11: MLP 16 -> 16 (ELU) -> 1, made non-negative by softplus (no dead units at the start; the appendix
  lists ReLU).
A sample that no source view sees gets density exactly 0.

Colour head (the paper leaves it open): IBRNet-style blending. Each valid view scores its source
colour from its gated feature and view-direction difference (MLP C + 4 -> 16 -> 1, ELU); a
softmax over the valid views blends the source colours at the projections. A sample no view sees
gets colour 0. Blending keeps colours in [0, 1] and generalises to unseen scenes by construction.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from .config import SRayConfig
from .cra import AttentionBlock


def masked_mean_var(x: Tensor, valid: Tensor, dim: int) -> tuple[Tensor, Tensor]:
    """Float32 mean and (biased) variance over ``dim`` of the valid entries of ``x``.

    x: (..., K, ..., D), ZERO wherever ``valid`` (same shape without D) is False. With n valid
    entries out of K, the (K - n) zeros add (K - n) mean^2 to the sum of squared deviations,
    which is subtracted again (two-pass variance, no E[x^2] - E[x]^2 cancellation). Entries
    without any valid element give 0.
    """
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

    def forward(self, space: Tensor, valid: Tensor, dirs: Tensor, src_rgb: Tensor) -> tuple[Tensor, Tensor]:
        """space: (R, m, N, C) (ignored where invalid); valid: (R, m, N); dirs: (R, m, N, 4);
        src_rgb: (R, m, N, 3) source colours at the projections. Returns sigma (R, N), rgb (R, N, 3)."""
        keep = valid[..., None].to(space.dtype)
        gated = self.feature(space) * (torch.sigmoid(self.gate(space)) * keep)  # (R, m, N, C), 0 if invalid
        mean, var = masked_mean_var(gated, valid, dim=1)  # (R, N, C) each
        seen = valid.any(dim=1)  # (R, N)
        g = self.fuse(torch.cat([mean, var], dim=-1))  # (R, N, 16)
        g = self.ray_attention(g, seen)  # (R, N, 16)
        raw = self.density(g).squeeze(-1).float()  # (R, N)
        sigma = F.softplus(raw) * seen.float()

        score = self.colour_score(torch.cat([gated, dirs.to(gated.dtype)], dim=-1)).squeeze(-1)  # (R, m, N)
        blend = masked_softmax(score, valid, dim=1)  # (R, m, N)
        rgb = (blend[..., None] * src_rgb.float()).sum(dim=1)  # (R, N, 3), float32 outside autocast
        return sigma, rgb
