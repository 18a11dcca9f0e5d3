"""Geometry-aware net: masked cross-view statistics, zero density where unseen, convex colour blend."""

from __future__ import annotations

import torch

from sray.model.config import SRayConfig
from sray.model.geometry_net import GeometryNet, masked_mean_var, masked_softmax


def test_masked_mean_var_matches_a_per_sample_loop() -> None:
    torch.manual_seed(2)
    valid = torch.rand(3, 5, 4) < 0.6
    valid[0, :, 1] = False
    x = (torch.randn(3, 5, 4, 6) * 3 + 5) * valid[..., None]
    mean, var = masked_mean_var(x, valid, dim=1)
    for r in range(3):
        for k in range(4):
            sel = x[r, valid[r, :, k], k].double()  # (n, 6)
            if len(sel) == 0:
                assert (mean[r, k] == 0).all() and (var[r, k] == 0).all()
                continue
            torch.testing.assert_close(mean[r, k].double(), sel.mean(0), rtol=1e-5, atol=1e-5)
            torch.testing.assert_close(var[r, k].double(), sel.var(0, unbiased=False), rtol=1e-4, atol=1e-4)


def test_masked_softmax_ignores_invalid_entries() -> None:
    logits = torch.tensor([[1.0, 2.0, 3.0], [0.5, -1.0, 9.0]])
    valid = torch.tensor([[True, False, True], [False, False, False]])
    p = masked_softmax(logits, valid, dim=1)
    e1, e3 = torch.exp(torch.tensor(1.0)), torch.exp(torch.tensor(3.0))
    torch.testing.assert_close(p[0], torch.stack([e1, torch.tensor(0.0), e3]) / (e1 + e3))
    assert (p[1] == 0).all()


def test_density_is_zero_where_no_view_sees_and_colour_is_a_blend() -> None:
    torch.manual_seed(3)
    net = GeometryNet(SRayConfig())
    space = torch.randn(4, 5, 6, 32)
    valid = torch.rand(4, 5, 6) < 0.5
    valid[1, :, 2] = False
    rgb = torch.rand(4, 5, 6, 3)
    sigma, colour = net(space, valid, torch.randn(4, 5, 6, 4), rgb)
    seen = valid.any(1)
    assert (sigma[~seen] == 0).all() and (sigma[seen] > 0).all()
    assert (colour[~seen] == 0).all()
    lo = rgb.masked_fill(~valid[..., None], 2.0).amin(1)
    hi = rgb.masked_fill(~valid[..., None], -1.0).amax(1)
    assert ((colour >= lo - 1e-6) & (colour <= hi + 1e-6))[seen].all()
