"""``sray bench profile --workload attention-keys``: where the sliced CPU kernel beats SDPA's flash kernel.

The intra-view stage of one 256-ray piece (the CPU's training piece and render chunk), 8 source views,
4 heads of 8 channels, at several sample counts (the stage's key length), timed forward only (a render)
and forward + backward (a training step) with SDPA's flash kernel and with ``sliced_attention``. The
table shows the kernel ``model.sliced_attention.attention`` picks for each; on another CPU, rerun it (and
the whole-step trials in docs/performance.md) before trusting the ranges there.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F
from torch import Tensor

from sray.jobs.bench.probes import time_call
from sray.jobs.bench.render_levers import HEAD_DIM, HEADS, with_backward
from sray.model.sliced_attention import SLICED_KEYS, sliced_attention


def _stage_inputs(rays: int, samples: int, views: int, grad: bool) -> tuple[Tensor, Tensor, Tensor]:
    """Tokens (R, N, m, C), the q/k/v weight (3C, C) and the intra-view key mask (R, m * heads, 1, N) with
    one key kept per query."""
    gen = torch.Generator().manual_seed(samples)
    c = HEADS * HEAD_DIM
    tokens = torch.randn(rays, samples, views, c, generator=gen).requires_grad_(grad)
    weight = (torch.randn(3 * c, c, generator=gen) * c ** -0.5).requires_grad_(grad)
    mask = torch.rand(rays, views * HEADS, 1, samples, generator=gen) > 0.2
    mask[..., 0] = True  # every query keeps a key, as the model's key masks guarantee
    return tokens, weight, mask


def _timed(kernel: Callable[..., Tensor], rays: int, samples: int, views: int, grad: bool, repeats: int) -> float:
    """Median seconds of the stage as the fast block runs it: q, k and v as three linears of the tokens,
    their (R, m * heads, N, d) views, ``kernel``; with ``grad``, the backward of a dense upstream gradient
    to the tokens and the weight (an ``out.sum()`` would hand the kernels a stride-0 gradient, which
    sends batched matmuls down a per-matrix path that no training step takes)."""
    tokens, weight, mask = _stage_inputs(rays, samples, views, grad)
    c = HEADS * HEAD_DIM

    def stage() -> Tensor:
        q, k, v = (F.linear(tokens, weight[i * c:(i + 1) * c]).view(rays, samples, views * HEADS, HEAD_DIM)
                   .transpose(1, 2) for i in range(3))
        return kernel(q, k, v, mask)

    if grad:
        return time_call(with_backward(stage, (tokens, weight)), torch.device("cpu"), repeats)
    with torch.no_grad():
        return time_call(stage, torch.device("cpu"), repeats)


def key_length_table(samples: tuple[int, ...], rays: int = 256, views: int = 8, repeats: int = 3) -> str:
    """Milliseconds per intra-view stage with SDPA's flash kernel and with the sliced kernel, per sample
    count, forward and forward + backward, and which kernel ``attention`` uses there."""
    def flash(q: Tensor, k: Tensor, v: Tensor, mask: Tensor) -> Tensor:
        return F.scaled_dot_product_attention(q, k, v, attn_mask=mask)

    lines = ["| samples (keys) | pass | SDPA flash ms | sliced ms | flash / sliced | kernel used on a CPU |",
             "|---:|---|---:|---:|---:|---|"]
    for n in samples:
        for grad in (False, True):
            used = "sliced" if n in SLICED_KEYS and not grad else "SDPA flash"
            t_flash = _timed(flash, rays, n, views, grad, repeats)
            t_sliced = _timed(sliced_attention, rays, n, views, grad, repeats)
            lines.append(f"| {n} | {'forward + backward' if grad else 'forward'} | {1e3 * t_flash:.3g} | "
                         f"{1e3 * t_sliced:.3g} | {t_flash / t_sliced:.2f} | {used} |")
    return "\n".join(lines)
