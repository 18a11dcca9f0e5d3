"""Attention for the fast path: SDPA, or in a CPU render over 24 to 64 keys, scores built in cache-sized slices.

SDPA's CPU flash kernel walks each (batch, head) in blocks and keeps a running softmax; with the
model's 8-channel heads it spends its time on that bookkeeping, not on matmuls (docs/performance.md).
When the key sequence is short, the whole (L_q, L_k) score matrix of a few rows of the batch is small.
Built with one matmul, offset by the mask, softmaxed and multiplied by v, a slice of rows at a time so
that a slice's scores stay in the CPU's last-level cache, the same attention is faster there at the
intra-view stage's usual key counts. Whole renders and training steps timed side by side
(docs/performance.md) set where it is used: a render (no gradient) at 24 to 64 keys, 1.17x per view at 24
samples. A training step gained 3-7% at 24 and 32 samples, within the run-to-run spread of the
benchmark, and nothing at 64 while every slice's stored softmax cost 0.6 GiB, so training keeps SDPA.
Below 24 keys (the cross-view stage attends over the 4 to 8 source views, where the two kernels are even)
and on a GPU, SDPA's kernels stay. `sray bench profile --workload attention-keys` times the two kernels
on one stage per key count.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

SLICE_SCORES = 1 << 20
"""Score elements per slice: 4 MiB in fp32, which with its softmax stays in this CPU's 32 MiB L3."""

SLICED_KEYS = range(24, 65)
"""Key counts at which the sliced kernel replaces SDPA in a CPU render (no gradient taken)."""


def attention(q: Tensor, k: Tensor, v: Tensor, key_mask: Tensor) -> Tensor:
    """Scaled dot-product attention with a boolean key mask, by the faster kernel for the shape and pass.

    q: (B, H, L_q, d); k, v: (B, H, L_k, d); key_mask: (B or 1, H or 1, 1, L_k) bool, True = attend, at
    least one key per query. Returns (B, H, L_q, d), the values of ``F.scaled_dot_product_attention``.
    """
    grad = torch.is_grad_enabled() and (q.requires_grad or k.requires_grad or v.requires_grad)
    if q.device.type == "cpu" and not grad and k.shape[-2] in SLICED_KEYS:
        return sliced_attention(q, k, v, key_mask)
    return F.scaled_dot_product_attention(q, k, v, attn_mask=key_mask)


def sliced_attention(q: Tensor, k: Tensor, v: Tensor, key_mask: Tensor, slice_scores: int = SLICE_SCORES) -> Tensor:
    """softmax(q k^T / sqrt(d) + mask) v over slices of the batch, each slice's scores materialised.

    Shapes as in ``attention``; ``slice_scores`` bounds the score elements (rows x H x L_q x L_k) of one
    slice. Differentiable through autograd: each slice keeps its own softmax for the backward, so the
    backward also works slice by slice; ``split`` (not indexing) cuts the slices, so the inputs'
    gradients are joined by one concatenation instead of one zero-filled full-size tensor per slice.
    """
    batch, heads, l_q, _ = q.shape
    l_k = k.shape[-2]
    bias = torch.zeros(key_mask.shape, dtype=q.dtype, device=q.device).masked_fill_(~key_mask, float("-inf"))
    rows = max(1, slice_scores // (heads * l_q * l_k))
    scale = q.shape[-1] ** -0.5
    biases = bias.split(rows) if bias.shape[0] > 1 else [bias] * -(-batch // rows)
    outs = []
    for q_part, k_part, v_part, b_part in zip(q.split(rows), k.split(rows), v.split(rows), biases):
        scores = torch.matmul(q_part * scale, k_part.transpose(-1, -2)) + b_part.to(q_part.dtype)  # (rows, H, Lq, Lk)
        outs.append(torch.matmul(torch.softmax(scores, dim=-1).to(v_part.dtype), v_part))
    return outs[0] if len(outs) == 1 else torch.cat(outs)
