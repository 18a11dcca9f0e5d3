"""Semantic-aware weight net: bounded per-view weights that build the semantic ray s = sum_i w_i F''_i.

The paper asks for w in C(tau) = {tau/m < w_i < 1/(tau m), sum_i w_i = 1}. Here m is the number
of views that VALIDLY see the sample (``n`` below): an invalid view gets weight exactly 0, which is
the only way a view that sees nothing can have no influence while the others stay bounded below.

The net's raw output a_i per valid view becomes a weight by the ``radial`` map (``radial_weights``), which gives
exactly 0 to invalid views, w = 1 for n = 1, all 0 for n = 0, and the plain mean 1/n for tau = 1. Its raw outputs
are centred, e_i = a_i - mean(a), and with p = 1/tau - 1 (room above 1/n, in units of 1/n) and q = 1 - tau (room
below) its gauge g = max_i max(e_i / p, -e_i / q) >= 0 says how far e points towards the boundary:

    w_i = (1 + (1 - margin) e_i / (1 + g)) / n.

* sum: sum_i e_i = 0, so sum_i w_i = 1.
* bounds: for e_i > 0, e_i <= g p, so n w_i - 1 <= (1 - margin) p g / (1 + g) < p, i.e.
  w_i < (1 + p) / n = 1/(tau n); for e_i < 0 likewise n w_i - 1 > -q, i.e. w_i > tau / n.
* range: near e = 0 the map is the identity to first order (w = (1 + e) / n); as one e_i grows (or falls) alone,
  g -> infinity and w_i -> (1 + (1 - margin) p) / n (or (1 - (1 - margin) q) / n): both bounds are
  approached to within a relative (margin p / (1 + p)) or (margin q / tau).

Input of the net (37 = 32 + 4 + 1 channels at the default C = 32): the refined feature F''_i of
the token (C), the 4-d view-direction difference of ``reprojection.view_direction_difference``
and the fraction of the ray's N samples that view i sees (how much of the ray it observes).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from .config import SRayConfig

WEIGHT_MARGIN = 1e-3
"""``margin`` of the net's weights: the fraction of the weight range kept unused so the bounds stay strict when the
raw scores saturate in floating point."""


def radial_weights(logits: Tensor, valid: Tensor, tau: float, margin: float) -> Tensor:
    """Raw per-view outputs (..., m) and validity (..., m) -> float32 weights (..., m).

    Over the valid entries of each row the weights sum to 1 and obey tau/n < w_i < 1/(tau n), with
    both bounds approachable (the ``radial`` map of the module docstring); invalid entries get 0, a
    row without valid entries is all 0, and tau = 1 gives exactly 1/n.
    """
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
        """feats: (R, m, N, C) refined space; dirs: (R, m, N, 4); valid: (R, m, N) bool.

        Returns float32 weights (R, m, N), summing to 1 over the valid views of each sample.
        """
        seen = valid.to(feats.dtype).mean(dim=2, keepdim=True).expand_as(valid)  # (R, m, N)
        x = torch.cat([feats, dirs.to(feats.dtype), seen[..., None]], dim=-1)  # (R, m, N, C + 5)
        raw = self.mlp(x).squeeze(-1).float().transpose(1, 2)  # (R, N, m)
        return radial_weights(raw, valid.transpose(1, 2), self.tau, self.margin).transpose(1, 2)  # (R, m, N)
