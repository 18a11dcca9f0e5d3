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
    y = x + att @ wo.T + bo
    if block.ffn is not None:
        norm, lin1, _, lin2 = block.ffn
        hidden = (_naive_layer_norm(y, norm) @ lin1.weight.double().T + lin1.bias.double()).clamp_min(0)
        y = y + hidden @ lin2.weight.double().T + lin2.bias.double()
    return y


def _case(variant: str, seed: int = 0) -> tuple[CrossReprojectionAttention, torch.Tensor, torch.Tensor]:
    torch.manual_seed(seed)
    cfg = SRayConfig(feat_dim=8, n_heads=2, attention=variant, n_coarse=5, geo_hidden=(8, 4))
    module = CrossReprojectionAttention(cfg, 5)
    space = torch.randn(3, 4, 5, 8)  # (R, m, N, C)
    valid = torch.rand(3, 4, 5) < 0.7
    valid[1, 2] = False  # a view that sees no sample of ray 1
    valid[2, :, 3] = False  # a sample of ray 2 that no view sees
    valid[0, 0, 0] = True
    return module, space, valid


def test_dense_equals_naive_loop_attention() -> None:
    module, space, valid = _case("dense")
    got = module(space, valid)
    r, m, n, c = space.shape
    x = space + module.pos.detach()
    for ray in range(r):
        ref = _naive_block(module.dense, x[ray].reshape(m * n, c), valid[ray].reshape(m * n))
        torch.testing.assert_close(got[ray].double(), ref.view(m, n, c), rtol=1e-5, atol=1e-5)
    all_invalid = torch.zeros_like(valid)
    assert torch.isfinite(module(space, all_invalid)).all()


@pytest.mark.parametrize("ffn_mult", [0, 2])
def test_full_cra_equals_naive_intra_then_cross(ffn_mult: int) -> None:
    torch.manual_seed(1)
    cfg = SRayConfig(feat_dim=8, n_heads=2, attention="full", n_coarse=5, ffn_mult=ffn_mult, geo_hidden=(8, 4))
    module = CrossReprojectionAttention(cfg, 5)
    _, space, valid = _case("full")
    got = module(space, valid).double()
    r, m, n, c = space.shape
    x = (space + module.pos.detach()).double()
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
        module, space, valid = _case(variant)
        changed = space.clone()
        changed[~valid] = torch.randn(int((~valid).sum()), 8) * 100
        a, b = module(space, valid), module(changed, valid)
        torch.testing.assert_close(a[valid], b[valid], rtol=1e-5, atol=1e-5, msg=variant)


def test_variants_hold_only_their_layers() -> None:
    present = {}
    for variant in ("full", "intra", "cross", "none", "dense"):
        module, _, _ = _case(variant)
        present[variant] = tuple(getattr(module, k) is not None for k in ("pos", "intra", "cross", "dense"))
    assert present == {"full": (True, True, True, False), "intra": (True, True, False, False),
                       "cross": (False, False, True, False), "none": (False, False, False, False),
                       "dense": (True, False, False, True)}
    module, space, valid = _case("none")
    assert module(space, valid) is space
