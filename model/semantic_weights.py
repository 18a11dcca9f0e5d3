"""Semantic-aware weight net: bounded per-view weights that build the semantic ray s = sum_i w_i F''_i.

The paper asks for w in C(tau) = {tau/m < w_i < 1/(tau m), sum_i w_i = 1}. Here m is the number
of views that VALIDLY see the sample (``n`` below): an invalid view gets weight exactly 0, which is
the only way a view that sees nothing can have no influence while the others stay bounded below.

Parametrisation (``bounded_weights``). The net gives a score s_i in [0, 1] per valid view (the
appendix's sigmoid, L3). With the valid views' mean score s_bar, d_i = s_i - s_bar and
kappa = (1 - margin)(1 - tau) n / (n - 1) (kappa = 0 when n <= 1):

    w_i = (1 + kappa d_i) / n.

Proof of the constraints, for any scores (saturated 0 and 1 included):
* sum: sum_i d_i = sum_i s_i - n s_bar = 0, so sum_i w_i = (n + kappa * 0) / n = 1.
* bounds: |d_i| <= (n - 1) / n because d_i = ((n - 1) s_i - sum_{j != i} s_j) / n with all scores
  in [0, 1]; hence |kappa d_i| <= (1 - margin)(1 - tau) < 1 - tau for tau < 1, and
  w_i lies in [(1 - (1-margin)(1-tau)) / n, (1 + (1-margin)(1-tau)) / n], strictly inside
  (tau / n, (2 - tau) / n). Finally (2 - tau) / n < 1 / (tau n) because
  tau (2 - tau) = 1 - (1 - tau)^2 < 1. The margin keeps both inequalities strict in floating
  point when a sigmoid saturates.
* tau = 1: kappa = 0 and w_i = 1/n exactly, the mean over valid views.
* n = 1: w = 1; n = 0 (no view sees the sample): all weights are 0 and the semantic ray is 0.

Input of the net (37 = 32 + 4 + 1 channels at the default C = 32): the refined feature F''_i of
the token (C), the 4-d view-direction difference of ``reprojection.view_direction_difference``
and the fraction of the ray's N samples that view i sees (how much of the ray it observes).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from .config import SRayConfig


def bounded_weights(score: Tensor, valid: Tensor, tau: float, margin: float) -> Tensor:
    """Scores (..., m) in [0, 1] and validity (..., m) -> float32 weights (..., m).

    Over the valid entries of each row the weights sum to 1 and obey
    tau/n < w_i < 1/(tau n) with n the row's number of valid entries (strict for tau < 1;
    exactly 1/n for tau = 1); invalid entries get 0; a row without valid entries is all 0.
    See the module docstring for the proof.
    """
    with torch.autocast(device_type=score.device.type, enabled=False):
        keep = valid.float()
        n = keep.sum(-1, keepdim=True)  # (..., 1)
        n_safe = n.clamp_min(1.0)
        s = score.float().clamp(0.0, 1.0) * keep
        d = (s - s.sum(-1, keepdim=True) / n_safe) * keep  # (..., m), sums to 0 over valid views
        kappa = (1.0 - margin) * (1.0 - tau) * n / (n - 1.0).clamp_min(1.0)  # 0 at n <= 1 (d = 0)
        return keep * (1.0 + kappa * d) / n_safe


class SemanticWeightNet(nn.Module):
    """MLP (C + 5 -> 16 -> 8 -> 1, ELU, sigmoid) scoring each view, mapped into C(tau)."""

    def __init__(self, cfg: SRayConfig) -> None:
        super().__init__()
        h1, h2 = cfg.weight_hidden
        self.tau, self.margin = cfg.tau, cfg.weight_margin
        self.mlp = nn.Sequential(nn.Linear(cfg.feat_dim + 5, h1), nn.ELU(), nn.Linear(h1, h2), nn.ELU(),
                                 nn.Linear(h2, 1))

    def forward(self, feats: Tensor, dirs: Tensor, valid: Tensor) -> Tensor:
        """feats: (R, m, N, C) refined space; dirs: (R, m, N, 4); valid: (R, m, N) bool.

        Returns float32 weights (R, m, N), summing to 1 over the valid views of each sample.
        """
        seen = valid.to(feats.dtype).mean(dim=2, keepdim=True).expand_as(valid)  # (R, m, N)
        x = torch.cat([feats, dirs.to(feats.dtype), seen[..., None]], dim=-1)  # (R, m, N, C + 5)
        score = torch.sigmoid(self.mlp(x).squeeze(-1).float())  # (R, m, N)
        w = bounded_weights(score.transpose(1, 2), valid.transpose(1, 2), self.tau, self.margin)
        return w.transpose(1, 2)  # (R, m, N)
