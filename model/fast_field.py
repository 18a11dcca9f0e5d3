"""The fast forward of ``SRayField`` (``Runtime.impl="fast"``): same parameters and values, fewer copies. Per-view
tensors stay in (R, N, m, C) order, so no transposed copy of M is made (docs/benchmarks/profile.md): q, k, v are
(R, N, m, C) views of the block's ``qkv`` handed to SDPA as strided views, intra-view attention with the views folded
into the head axis (R, m * heads, N, d), cross-view as (R * N, heads, m, d). The first linear layers of the weight
net and colour score act piecewise (W [a; b] = W_a a + W_b b), not on a concat."""

from __future__ import annotations

import torch.nn.functional as F
from torch import Tensor

from .cra import AttentionBlock, CrossReprojectionAttention
from .geometry_net import GeometryNet, blend_colours
from .semantic_weights import SemanticWeightNet, radial_weights
from .sliced_attention import attention


def _key_mask(valid: Tensor, dim: int) -> Tensor:
    """Keys an attention over ``dim`` may use: the valid ones, or all where none is valid (finite)."""
    return valid | ~valid.any(dim, keepdim=True)


def block_forward(block: AttentionBlock, x: Tensor, valid: Tensor, stage: str) -> Tensor:
    """One ``AttentionBlock`` on tokens x (R, N, m, C) with validity (R, N, m) at ``stage`` ``intra`` (over N per (ray,
    view)), ``cross`` (over m per (ray, sample)) or ``dense``: the reference block's values, (R, N, m, C)."""
    r, n, m, c = x.shape
    heads, d = block.heads, c // block.heads
    h = block.norm(x)
    w, b = block.qkv.weight, block.qkv.bias
    q, k, v = (F.linear(h, w[i * c:(i + 1) * c], b[i * c:(i + 1) * c]) for i in range(3))  # (R, N, m, C) each
    if stage == "intra":
        def split(t: Tensor) -> Tensor:
            return t.view(r, n, m * heads, d).transpose(1, 2)  # (R, m * heads, N, d)
        keys = _key_mask(valid, 1).transpose(1, 2)[:, :, None, None, :]  # (R, m, 1, 1, N)
        mask = keys.expand(r, m, heads, 1, n).reshape(r, m * heads, 1, n)
    elif stage == "cross":
        def split(t: Tensor) -> Tensor:
            return t.view(r * n, m, heads, d).transpose(1, 2)  # (R * N, heads, m, d)
        mask = _key_mask(valid, 2).reshape(r * n, 1, 1, m)
    else:
        def split(t: Tensor) -> Tensor:
            return t.view(r, n * m, heads, d).transpose(1, 2)  # (R, heads, N * m, d)
        mask = _key_mask(valid.reshape(r, n * m), 1)[:, None, None, :]
    att = attention(split(q), split(k), split(v), mask)
    return x + block.proj(att.transpose(1, 2).reshape(r, n, m, c))


def cra_forward(cra: CrossReprojectionAttention, space: Tensor, valid: Tensor, depth01: Tensor) -> Tensor:
    """``CrossReprojectionAttention.forward`` in (R, N, m, C) order: space, valid (R, N, m), depth01 (R, N)."""
    x = space
    if cra.depth_embedding is not None:
        x = x + cra.position_signal(depth01)[:, :, None].to(x.dtype)
    for stage in cra.stages:
        x = block_forward(getattr(cra, stage), x, valid, stage)
    return x


def weights_forward(net: SemanticWeightNet, feats: Tensor, dirs: Tensor, valid: Tensor) -> Tensor:
    """``SemanticWeightNet.forward`` in (R, N, m) order: float32 weights (R, N, m)."""
    c = feats.shape[-1]
    first = net.mlp[0]
    w = first.weight  # columns: feature (C), direction difference (4), seen fraction (1)
    seen = valid.to(feats.dtype).mean(dim=1, keepdim=True)  # (R, 1, m) fraction of the ray each view sees
    per_view = dirs.to(feats.dtype)  # (R, N, m, 4)
    hidden = (F.linear(feats, w[:, :c], first.bias) + F.linear(per_view, w[:, c:-1])
              + seen[..., None] * w[:, -1].to(feats.dtype))  # (R, N, m, h1)
    raw = net.mlp[1:](hidden).squeeze(-1).float()  # (R, N, m)
    return radial_weights(raw, valid, net.tau, net.margin)


def geometry_forward(net: GeometryNet, space: Tensor, valid: Tensor, dirs: Tensor,
                     src_rgb: Tensor) -> tuple[Tensor, Tensor]:
    """``GeometryNet.forward`` with every per-view input in (R, N, m, ...) order -> sigma (R, N), rgb (R, N, 3)."""
    gated, sigma = net.gated_density(space, valid, 2)
    c = space.shape[-1]
    first = net.colour_score[0]
    hidden = F.linear(gated, first.weight[:, :c], first.bias) + F.linear(dirs.to(gated.dtype), first.weight[:, c:])
    score = net.colour_score[1:](hidden).squeeze(-1)  # (R, N, m)
    return sigma, blend_colours(score, valid, src_rgb, 2)
