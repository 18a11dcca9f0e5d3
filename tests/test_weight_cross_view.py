"""Cross-view inputs of the semantic-aware weight net (``SRayConfig.weight_inputs = "cross-view"``).

The statistics against a naive per-sample loop in float64; the reference and fast forwards of the net agree for
both input settings and both weight maps; an invalid view's feature changes no weight; one valid view gives
distance and variance 0, none gives weights 0; the default net keeps the paper's shapes and only the first
layer widens with the option on.
"""

from __future__ import annotations

import pytest
import torch

from sray.model.config import WEIGHT_INPUTS, WEIGHT_MAPS, SRayConfig
from sray.model.fast_field import weights_forward
from sray.model.semantic_ray import SRayModel
from sray.model.semantic_weights import SemanticWeightNet, cross_view_stats

R, M, N, C = 3, 5, 7, 8
"""Rays, views, samples and channels of the random inputs."""


def _inputs(seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """feats (R, M, N, C), dirs (R, M, N, 4) and valid (R, M, N) with samples seen by no view and by one view."""
    gen = torch.Generator().manual_seed(seed)
    feats = torch.randn(R, M, N, C, generator=gen) * 2 + 1
    dirs = torch.randn(R, M, N, 4, generator=gen)
    valid = torch.rand(R, M, N, generator=gen) < 0.6
    valid[0, :, 0] = False  # no view sees sample 0 of ray 0
    valid[1, :, 1] = False
    valid[1, 2, 1] = True  # only view 2 sees sample 1 of ray 1
    return feats, dirs, valid


def _net(weight_inputs: str, weight_map: str, seed: int) -> SemanticWeightNet:
    """A weight net of C channels whose first layer weighs the statistics' inputs strongly (they matter)."""
    torch.manual_seed(seed)
    net = SemanticWeightNet(SRayConfig(feat_dim=C, n_heads=2, weight_inputs=weight_inputs, weight_map=weight_map))
    with torch.no_grad():
        net.mlp[0].weight[:, C + 4:-1].mul_(20.0)  # the statistics: between the directions and the seen fraction
    return net


def test_statistics_match_a_naive_per_sample_loop() -> None:
    feats, _, valid = _inputs(0)
    stats = cross_view_stats(feats, valid, view_dim=1)  # (R, M, N, 2)
    fast_order = cross_view_stats(feats.transpose(1, 2), valid.transpose(1, 2), view_dim=2).transpose(1, 2)
    want = torch.zeros(R, M, N, 2, dtype=torch.float64)
    for r in range(R):
        for n in range(N):
            views = [i for i in range(M) if valid[r, i, n]]
            if not views:
                continue
            f = feats[r, views, n].double()  # (k, C)
            mean = f.mean(0)
            variance = float(f.var(0, unbiased=False).mean())
            for i in views:  # the distance of each valid view; 0 for the others
                want[r, i, n, 0] = float(((feats[r, i, n].double() - mean) ** 2).sum()) / C
            want[r, :, n, 1] = variance  # one variance for every view of the sample
    assert stats.dtype == torch.float32
    torch.testing.assert_close(stats.double(), want, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(fast_order, stats, rtol=0, atol=1e-6)


def test_one_valid_view_gives_zero_and_no_valid_view_stays_finite() -> None:
    """Values and gradients: a distance of exactly 0 (the norm's kink) still has a finite gradient."""
    feats, dirs, valid = _inputs(1)
    feats.requires_grad_(True)
    stats = cross_view_stats(feats, valid, view_dim=1)
    assert (stats[1, :, 1] == 0).all() and (stats[0, :, 0] == 0).all()
    w = _net("cross-view", "radial", 0)(feats, dirs, valid)  # (R, M, N)
    assert torch.isfinite(w).all() and (w[0, :, 0] == 0).all() and w[1, 2, 1] == 1.0
    (stats.sum() + (w * torch.randn(R, M, N)).sum()).backward()
    assert torch.isfinite(feats.grad).all() and (feats.grad[0, :, 0] == 0).all()


def test_statistics_are_float32_under_bf16_autocast() -> None:
    """bf16 features (a CPU autocast training step): the statistics are taken in float32, the weights finite."""
    feats, dirs, valid = _inputs(2)
    low = feats.bfloat16()
    with torch.autocast("cpu", dtype=torch.bfloat16):
        stats = cross_view_stats(low, valid, view_dim=1)
        w = _net("cross-view", "radial", 0)(low, dirs, valid)
    assert stats.dtype == w.dtype == torch.float32 and torch.isfinite(w).all()
    torch.testing.assert_close(stats, cross_view_stats(low.float(), valid, view_dim=1), rtol=0, atol=0)


@pytest.mark.parametrize("weight_map", WEIGHT_MAPS)
@pytest.mark.parametrize("weight_inputs", WEIGHT_INPUTS)
def test_fast_forward_equals_the_reference_forward(weight_inputs: str, weight_map: str) -> None:
    for seed in range(3):
        feats, dirs, valid = _inputs(seed)
        net = _net(weight_inputs, weight_map, seed)
        ref = net(feats, dirs, valid)  # (R, M, N)
        fast = weights_forward(net, feats.transpose(1, 2), dirs.transpose(1, 2), valid.transpose(1, 2))
        torch.testing.assert_close(fast.transpose(1, 2), ref, rtol=0, atol=1e-6)


@pytest.mark.parametrize("weight_inputs", WEIGHT_INPUTS)
def test_an_invalid_views_feature_changes_no_weight(weight_inputs: str) -> None:
    """Garbage (large, of any sign) in place of every invalid view's feature: every weight stays bit for bit."""
    for seed in range(3):
        feats, dirs, valid = _inputs(seed)
        net = _net(weight_inputs, "radial", seed)
        garbage = torch.where(valid[..., None], feats, torch.randn(R, M, N, C) * 1e4)
        torch.testing.assert_close(net(garbage, dirs, valid), net(feats, dirs, valid), rtol=0, atol=0)
        fast = [weights_forward(net, f.transpose(1, 2), dirs.transpose(1, 2), valid.transpose(1, 2))
                for f in (garbage, feats)]
        torch.testing.assert_close(fast[0], fast[1], rtol=0, atol=0)


def test_the_default_keeps_the_papers_shapes_and_the_option_widens_only_the_first_layer() -> None:
    view, cross = (SRayModel(SRayConfig(weight_inputs=w)).state_dict() for w in ("view", "cross-view"))
    assert SRayConfig().weight_inputs == "view"
    for p in ("coarse", "fine"):
        shapes = [tuple(view[f"{p}.view_weights.mlp.{k}.{t}"].shape) for k in (0, 2, 4) for t in ("weight", "bias")]
        assert shapes == [(16, 37), (16,), (8, 16), (8,), (1, 8), (1,)]  # the appendix's 37 -> 16 -> 8 -> 1
    assert view.keys() == cross.keys()
    wider = {k for k in view if view[k].shape != cross[k].shape}
    assert wider == {"coarse.view_weights.mlp.0.weight", "fine.view_weights.mlp.0.weight"}
    assert cross["coarse.view_weights.mlp.0.weight"].shape == (16, 39)
