"""Attention for the fast path: SDPA, or in a CPU render over 24 to 64 keys, scores built in cache-sized slices (one
matmul, mask, softmax, matmul per slice): faster there than SDPA's CPU flash kernel, whose running-softmax bookkeeping
dominates with 8-channel heads (docs/performance.md; ``sray bench profile --workload attention-keys``)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

SLICE_SCORES = 1 << 20
"""Score elements per slice: 4 MiB in fp32, which with its softmax stays in this CPU's 32 MiB L3."""

SLICED_KEYS = range(24, 65)
"""Key counts at which the sliced kernel replaces SDPA in a CPU render (no gradient taken)."""


def attention(q: Tensor, k: Tensor, v: Tensor, key_mask: Tensor) -> Tensor:
    """``F.scaled_dot_product_attention``'s values by the faster kernel for the shape and pass: q (B, H, L_q, d),
    k, v (B, H, L_k, d), key_mask (B or 1, H or 1, 1, L_k) bool (True = attend, one key at least) -> (B, H, L_q, d)."""
    grad = torch.is_grad_enabled() and (q.requires_grad or k.requires_grad or v.requires_grad)
    if q.device.type == "cpu" and not grad and k.shape[-2] in SLICED_KEYS:
        return sliced_attention(q, k, v, key_mask)
    return F.scaled_dot_product_attention(q, k, v, attn_mask=key_mask)


def sliced_attention(q: Tensor, k: Tensor, v: Tensor, key_mask: Tensor, slice_scores: int = SLICE_SCORES) -> Tensor:
    """softmax(q k^T / sqrt(d) + mask) v over slices of the batch, shapes as ``attention``; ``slice_scores`` bounds
    one slice's score elements (rows x H x L_q x L_k). Differentiable slice by slice; ``split`` (not indexing)
    cuts the slices, so the inputs' gradients are joined by one concatenation."""
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
