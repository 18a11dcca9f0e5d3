"""Semantic-aware weight net: bounded per-view weights that build the semantic ray s = sum_i w_i F''_i. The paper
asks for tau/m < w_i < 1/(tau m), sum_i w_i = 1; m is here the number n of views validly seeing the sample (an
invalid view gets exactly 0). The ``radial`` map centres the raw outputs, e_i = a_i - mean(a), and with
p = 1/tau - 1, q = 1 - tau and gauge g = max_i max(e_i / p, -e_i / q) >= 0 sets
``w_i = (1 + (1 - margin) e_i / (1 + g)) / n``: sum_i e_i = 0 gives sum 1, e_i <= g p gives w_i < 1/(tau n) (and
likewise w_i > tau / n), both bounds approachable; tau = 1 is the plain mean. Input (C + 5): the refined feature,
the 4-d view-direction difference and the fraction of the ray's samples the view sees."""

from __future__ import annotations

import torch
from torch import Tensor, nn

from .config import SRayConfig

WEIGHT_MARGIN = 1e-3
"""``margin``: the fraction of the weight range kept unused, so the bounds stay strict when raw scores saturate."""


def radial_weights(logits: Tensor, valid: Tensor, tau: float, margin: float) -> Tensor:
    """Raw per-view outputs (..., m) and validity (..., m) -> float32 weights (..., m) by the ``radial`` map
    (module doc): over each row's valid entries they sum to 1 within tau/n < w_i < 1/(tau n); invalid entries 0."""
    with torch.autocast(device_type=logits.device.type, enabled=False):
        keep = valid.float()
        n = keep.sum(-1, keepdim=True)  # (..., 1)
        n_safe = n.clamp_min(1.0)
        if tau >= 1.0:
            return keep / n_safe
        a = logits.float() * keep
        e = (a - a.sum(-1, keepdim=True) / n_safe) * keep  # (..., m), sums to 0 over valid views
        above, below = 1.0 / tau - 1.0, 1.0 - tau
        gauge = torch.maximum(e / above, -e / below).amax(-1, keepdim=True).clamp_min(0.0)  # (..., 1)
        return keep * (1.0 + (1.0 - margin) * e / (1.0 + gauge)) / n_safe


class SemanticWeightNet(nn.Module):
    """MLP (C + 5 -> 16 -> 8 -> 1, ELU) scoring each view, mapped into C(tau) by :func:`radial_weights`."""

    def __init__(self, cfg: SRayConfig) -> None:
        super().__init__()
        h1, h2 = cfg.weight_hidden
        self.tau, self.margin = cfg.tau, WEIGHT_MARGIN
        self.mlp = nn.Sequential(nn.Linear(cfg.feat_dim + 5, h1), nn.ELU(), nn.Linear(h1, h2), nn.ELU(),
                                 nn.Linear(h2, 1))

    def forward(self, feats: Tensor, dirs: Tensor, valid: Tensor) -> Tensor:
        """feats (R, m, N, C), dirs (R, m, N, 4), valid (R, m, N) -> float32 weights (R, m, N) (module doc)."""
        seen = valid.to(feats.dtype).mean(dim=2, keepdim=True).expand_as(valid)  # (R, m, N)
        x = torch.cat([feats, dirs.to(feats.dtype), seen[..., None]], dim=-1)  # (R, m, N, C + 5)
        raw = self.mlp(x).squeeze(-1).float().transpose(1, 2)  # (R, N, m)
        return radial_weights(raw, valid.transpose(1, 2), self.tau, self.margin).transpose(1, 2)  # (R, m, N)
