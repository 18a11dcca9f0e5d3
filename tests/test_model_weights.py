"""The semantic-aware weights stay inside C(tau) for any scores (property test), the radial map can
approach both bounds, and tau = 1 is the mean."""

from __future__ import annotations

import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from sray.model.config import SRayConfig
from sray.model.semantic_weights import SemanticWeightNet, radial_weights

_logit = st.one_of(st.floats(-30, 30), st.sampled_from([-1e4, -100.0, 0.0, 100.0, 1e4]))


@settings(max_examples=200, deadline=None)
@given(m=st.integers(1, 12), tau=st.floats(0.01, 0.99), data=st.data())
def test_weights_obey_the_bounds_and_sum_to_one(m: int, tau: float, data: st.DataObject) -> None:
    logits = torch.tensor(data.draw(st.lists(_logit, min_size=m, max_size=m)), dtype=torch.float32)
    valid = torch.tensor(data.draw(st.lists(st.booleans(), min_size=m, max_size=m)))
    w = radial_weights(logits, valid, tau, margin=1e-3)
    n = int(valid.sum())
    assert w.dtype == torch.float32
    assert (w[~valid] == 0).all()
    if n == 0:
        assert (w == 0).all()
        return
    wv = w[valid].double()
    assert (wv > tau / n).all(), (wv, tau / n)
    assert (wv < 1 / (tau * n)).all(), (wv, 1 / (tau * n))
    torch.testing.assert_close(wv.sum(), torch.tensor(1.0, dtype=torch.float64), rtol=0, atol=2e-6)


def test_radial_weights_come_within_one_percent_of_both_bounds() -> None:
    """At m = 8, tau = 0.7 one view alone pushed up (down) gets within 1% of 1/(tau m) (tau/m)."""
    tau, m = 0.7, 8
    every = torch.ones(m, dtype=torch.bool)
    for push in (10.0, 100.0, 1e4):
        high = radial_weights(torch.tensor([push] + [0.0] * (m - 1)), every, tau, margin=1e-3)
        low = radial_weights(torch.tensor([-push] + [0.0] * (m - 1)), every, tau, margin=1e-3)
        assert float(high.max()) < 1 / (tau * m) and float(low.min()) > tau / m
    assert float(high[0]) > 0.99 / (tau * m), (float(high[0]), 1 / (tau * m))
    assert float(low[0]) < 1.01 * tau / m, (float(low[0]), tau / m)
    # near zero the map is the identity around the mean to first order: w = (1 + e) / m + O(e^2)
    small = torch.tensor([1e-4, -1e-4] + [0.0] * (m - 2))
    torch.testing.assert_close(radial_weights(small, every, tau, margin=0.0), (1 + small) / m, rtol=1e-6, atol=1e-7)


def test_tau_one_is_exactly_the_mean_over_valid_views() -> None:
    torch.manual_seed(0)
    cfg = SRayConfig(tau=1.0)
    net = SemanticWeightNet(cfg)
    feats = torch.randn(3, 5, 7, cfg.feat_dim)
    dirs = torch.randn(3, 5, 7, 4)
    valid = torch.rand(3, 5, 7) < 0.6
    w = net(feats, dirs, valid)
    n = valid.sum(1, keepdim=True).clamp_min(1).float()
    torch.testing.assert_close(w, valid.float() / n, rtol=0, atol=0)
    semantic = (w[..., None] * feats).sum(1)
    mean = (feats * valid[..., None]).sum(1) / n[..., None].squeeze(1)
    torch.testing.assert_close(semantic, mean, rtol=1e-6, atol=1e-6)


def test_net_weights_ignore_invalid_views_and_sum_to_one() -> None:
    torch.manual_seed(1)
    cfg = SRayConfig()
    net = SemanticWeightNet(cfg)
    feats = torch.randn(4, 6, 9, cfg.feat_dim) * 10
    valid = torch.rand(4, 6, 9) < 0.5
    w = net(feats, torch.randn(4, 6, 9, 4), valid)
    assert (w[~valid] == 0).all()
    n = valid.sum(1)
    torch.testing.assert_close(w.sum(1)[n > 0], torch.ones(int((n > 0).sum())), rtol=0, atol=2e-6)
    nv = n[..., None].expand(4, 9, 6).transpose(1, 2)[valid].float()
    assert (w[valid] > cfg.tau / nv).all() and (w[valid] < 1 / (cfg.tau * nv)).all()

