"""The fast forward of ``SRayField`` (``Runtime.impl="fast"``): same parameters, same values, fewer copies.

The reference forward keeps the contextual space M in (R, m, N, C) order and transposes it to
(R, N, m, C) and back around every cross-view attention: full copies of the largest tensors, which
the profile (docs/benchmarks.md, "Profiles") shows as ``copy_`` and ``cat`` time. Here every per-view tensor
lives in (R, N, m, C) order from the gather on, and each attention stage hands
``scaled_dot_product_attention`` strided views instead of copies:

* q, k and v are computed as three separate (R, N, m, C) tensors (the rows of the block's ``qkv``
  weight), so the view axis m and the head axis merge into one stride;
* intra-view attention (over the N samples of each (ray, view)) folds the views into SDPA's head
  axis: (R, m * heads, N, d); heads never mix, so this is attention per (ray, view, head);
* cross-view attention (over the m views of each (ray, sample)) is (R * N, heads, m, d);
* ``dense`` attends over all N * m tokens of a ray (the order of the tokens does not matter to
  attention as long as keys and mask follow it);
* SDPA's output comes back as (batch, L, heads, d) memory, i.e. (R, N, m, C) again;
* in a CPU render (no gradient), the intra-view stage at 24 to 64 samples runs ``sliced_attention``
  instead of SDPA's flash kernel: the same attention, scores built in cache-sized slices.
The first linear layers of the weight net and of the colour score are applied piecewise to their
inputs instead of to a concatenation (W [a; b] = W_a a + W_b b), which saves two more copies.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from .cra import AttentionBlock, CrossReprojectionAttention
from .geometry_net import GeometryNet, masked_mean_var, masked_softmax
from .semantic_weights import SemanticWeightNet, radial_weights
from .sliced_attention import attention


def _key_mask(valid: Tensor, dim: int) -> Tensor:
    """Keys an attention over ``dim`` may use: the valid ones, or all where none is valid (finite)."""
    return valid | ~valid.any(dim, keepdim=True)


def block_forward(block: AttentionBlock, x: Tensor, valid: Tensor, stage: str) -> Tensor:
    """One ``AttentionBlock`` on tokens x (R, N, m, C) with validity (R, N, m); ``stage`` is
    ``intra`` (over N per (ray, view)), ``cross`` (over m per (ray, sample)) or ``dense`` (over all).
    Returns (R, N, m, C), the reference block's values in this order."""
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
    """``CrossReprojectionAttention.forward`` in (R, N, m, C) order: space (R, N, m, C), valid (R, N, m),
    depth01 (R, N) -> (R, N, m, C)."""
    x = space
    if cra.depth_embedding is not None:
        x = x + cra.position_signal(depth01)[:, :, None].to(x.dtype)
    for stage in cra.stages:
        x = block_forward(getattr(cra, stage), x, valid, stage)
    return x


def weights_forward(net: SemanticWeightNet, feats: Tensor, dirs: Tensor, valid: Tensor) -> Tensor:
    """``SemanticWeightNet.forward`` in (R, N, m) order: feats (R, N, m, C), dirs (R, N, m, 4),
    valid (R, N, m) -> float32 weights (R, N, m)."""
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
    """``GeometryNet.forward`` in (R, N, m) order: space (R, N, m, C), valid (R, N, m), dirs (R, N, m, 4),
    src_rgb (R, N, m, 3) -> sigma (R, N), rgb (R, N, 3)."""
    keep = valid[..., None].to(space.dtype)
    gated = net.feature(space) * (torch.sigmoid(net.gate(space)) * keep)  # (R, N, m, C), 0 if invalid
    mean, var = masked_mean_var(gated, valid, dim=2)  # (R, N, C) each
    seen = valid.any(dim=2)  # (R, N)
    g = net.fuse(torch.cat([mean, var], dim=-1))  # (R, N, 16)
    g = net.ray_attention(g, seen)
    sigma = F.softplus(net.density(g).squeeze(-1).float()) * seen.float()
    c = space.shape[-1]
    first = net.colour_score[0]
    hidden = F.linear(gated, first.weight[:, :c], first.bias) + F.linear(dirs.to(gated.dtype), first.weight[:, c:])
    score = net.colour_score[1:](hidden).squeeze(-1)  # (R, N, m)
    blend = masked_softmax(score, valid, dim=2)  # (R, N, m)
    rgb = (blend[..., None] * src_rgb.float()).sum(dim=2)  # (R, N, 3)
    return sigma, rgb
