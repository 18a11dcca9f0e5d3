"""Cross-Reprojection Attention variants against a naive attention written with Python loops."""

from __future__ import annotations

import math

import pytest
import torch

from sray.model.config import SRayConfig
from sray.model.cra import AttentionBlock, CrossReprojectionAttention


@torch.no_grad()
def _naive_layer_norm(x: torch.Tensor, norm: torch.nn.LayerNorm) -> torch.Tensor:
    """Row-by-row layer norm in float64: x (L, D)."""
    n, d = x.shape
    out = torch.zeros_like(x)
    for i in range(n):
        mean = sum(float(x[i, c]) for c in range(d)) / d
        var = sum((float(x[i, c]) - mean) ** 2 for c in range(d)) / d
        out[i] = (x[i] - mean) / math.sqrt(var + norm.eps) * norm.weight.double() + norm.bias.double()
    return out


@torch.no_grad()
def _naive_block(block: AttentionBlock, x: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """One sequence through ``block`` with explicit loops, float64: x (L, D), valid (L,) -> (L, D)."""
    x = x.double()
    n, d = x.shape
    heads, dh = block.heads, d // block.heads
    wqkv, bqkv = block.qkv.weight.double(), block.qkv.bias.double()
    wo, bo = block.proj.weight.double(), block.proj.bias.double()
    keys = [j for j in range(n) if valid[j]] or list(range(n))
    qkv = _naive_layer_norm(x, block.norm) @ wqkv.T + bqkv  # (L, 3D)
    q, k, v = qkv[:, :d], qkv[:, d:2 * d], qkv[:, 2 * d:]
    att = torch.zeros(n, d, dtype=torch.float64)
    for h in range(heads):
        sl = slice(h * dh, (h + 1) * dh)
        for i in range(n):
            scores = [float(q[i, sl] @ k[j, sl]) / math.sqrt(dh) for j in keys]
            top = max(scores)
            expw = [math.exp(s - top) for s in scores]
            total = sum(expw)
            for j, e in zip(keys, expw):
                att[i, sl] += e / total * v[j, sl]
    return x + att @ wo.T + bo


@torch.no_grad()
def _naive_position(module: CrossReprojectionAttention, depth01: torch.Tensor) -> torch.Tensor:
    """The depth embedding written out: [d, sin(pi 2^k d), cos(pi 2^k d) for k < L] @ W^T + b, float64.

    depth01 (R, N) -> (R, N, C)."""
    linear = module.depth_embedding[1]
    n_freqs = (linear.in_features - 1) // 2
    d = depth01.double()
    feats = [d]
    for k in range(n_freqs):
        feats += [torch.sin(math.pi * 2.0**k * d), torch.cos(math.pi * 2.0**k * d)]
    return torch.stack(feats, -1) @ linear.weight.double().T + linear.bias.double()


def _case(variant: str, seed: int = 0) -> tuple[CrossReprojectionAttention, torch.Tensor, torch.Tensor,
                                               torch.Tensor]:
    torch.manual_seed(seed)
    cfg = SRayConfig(feat_dim=8, n_heads=2, attention=variant, n_coarse=5, geo_hidden=(8, 4))
    module = CrossReprojectionAttention(cfg)
    space = torch.randn(3, 4, 5, 8)  # (R, m, N, C)
    valid = torch.rand(3, 4, 5) < 0.7
    valid[1, 2] = False  # a view that sees no sample of ray 1
    valid[2, :, 3] = False  # a sample of ray 2 that no view sees
    valid[0, 0, 0] = True
    depth01 = torch.sort(torch.rand(3, 5), dim=-1).values  # (R, N)
    return module, space, valid, depth01


def test_dense_equals_naive_loop_attention() -> None:
    module, space, valid, depth01 = _case("dense")
    got = module(space, valid, depth01)
    r, m, n, c = space.shape
    x = space.double() + _naive_position(module, depth01)[:, None]
    for ray in range(r):
        ref = _naive_block(module.dense, x[ray].reshape(m * n, c), valid[ray].reshape(m * n))
        torch.testing.assert_close(got[ray].double(), ref.view(m, n, c), rtol=1e-5, atol=1e-5)
    all_invalid = torch.zeros_like(valid)
    assert torch.isfinite(module(space, all_invalid, depth01)).all()


def test_full_cra_equals_naive_intra_then_cross() -> None:
    torch.manual_seed(1)
    cfg = SRayConfig(feat_dim=8, n_heads=2, attention="full", n_coarse=5, geo_hidden=(8, 4))
    module = CrossReprojectionAttention(cfg)
    _, space, valid, depth01 = _case("full")
    got = module(space, valid, depth01).double()
    r, m, n, c = space.shape
    x = space.double() + _naive_position(module, depth01)[:, None]
    mid = torch.zeros_like(x)
    for ray in range(r):
        for view in range(m):
            mid[ray, view] = _naive_block(module.intra, x[ray, view], valid[ray, view])
    ref = torch.zeros_like(x)
    for ray in range(r):
        for k in range(n):
            ref[ray, :, k] = _naive_block(module.cross, mid[ray, :, k], valid[ray, :, k])
    mask = valid[..., None].expand_as(ref)
    torch.testing.assert_close(got[mask], ref[mask], rtol=1e-5, atol=1e-5)


def test_invalid_keys_do_not_influence_valid_tokens() -> None:
    for variant in ("full", "intra", "cross", "dense"):
        module, space, valid, depth01 = _case(variant)
        changed = space.clone()
        changed[~valid] = torch.randn(int((~valid).sum()), 8) * 100
        a, b = module(space, valid, depth01), module(changed, valid, depth01)
        torch.testing.assert_close(a[valid], b[valid], rtol=1e-5, atol=1e-5, msg=variant)


def test_variants_hold_only_their_layers() -> None:
    present = {}
    for variant in ("full", "intra", "cross", "none", "dense"):
        module, _, _, _ = _case(variant)
        present[variant] = tuple(getattr(module, k, None) is not None
                                 for k in ("depth_embedding", "intra", "cross", "dense"))
    assert present == {"full": (True, True, True, False), "intra": (True, True, False, False),
                       "cross": (False, False, True, False), "none": (False, False, False, False),
                       "dense": (True, False, False, True)}
    module, space, valid, depth01 = _case("none")
    assert module(space, valid, depth01) is space


def test_position_signal_depends_on_depth_not_on_rank() -> None:
    """Samples at the same depths of rays with the same bounds get the same signal, whatever drew them."""
    from sray.model.field import normalised_depth
    from sray.model.rendering import merge_samples, sample_pdf, sample_uniform

    module, _, _, _ = _case("full")
    near, far = torch.full((2,), 0.5), torch.full((2,), 4.5)
    coarse = sample_uniform(near, far, 6, stratified=True, generator=torch.Generator().manual_seed(3))  # (2, 6)
    fine = sample_pdf(coarse, torch.rand(2, 6), near, far, 5, deterministic=False,
                      generator=torch.Generator().manual_seed(4))
    merged = merge_samples(coarse, fine)  # the coarse depths now sit at other ranks
    with torch.no_grad():
        sig_coarse = module.position_signal(normalised_depth(coarse, near, far))  # (2, 6, C)
        sig_merged = module.position_signal(normalised_depth(merged, near, far))  # (2, 11, C)
    for ray in range(2):
        ranks = [int((merged[ray] == z).nonzero()[0]) for z in coarse[ray]]
        assert ranks != list(range(6)), "the test needs coarse samples that moved rank"
        torch.testing.assert_close(sig_merged[ray, ranks], sig_coarse[ray], rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(sig_merged[ray, ranks].double(),
                                   _naive_position(module, normalised_depth(coarse, near, far))[ray],
                                   rtol=1e-5, atol=1e-5)
    other_bounds = module.position_signal(normalised_depth(coarse, near * 0.5, far * 2.0))
    assert not torch.allclose(other_bounds, sig_coarse), "the signal must follow the ray's bounds"
