"""The sliced CPU attention kernel against a naive per-(row, head, query) loop, and its dispatch rule."""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from sray.model.sliced_attention import SLICED_KEYS, attention, sliced_attention


def _naive(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Masked softmax attention written out query by query: exp of the shifted scores over their sum."""
    mask = mask.expand(q.shape[0], q.shape[1], 1, k.shape[2])
    rows = []
    for b in range(q.shape[0]):
        heads = []
        for h in range(q.shape[1]):
            keep = mask[b, h, 0]
            outs = []
            for i in range(q.shape[2]):
                scores = (k[b, h, keep] * q[b, h, i]).sum(-1) / math.sqrt(q.shape[-1])
                w = torch.exp(scores - scores.max())
                outs.append((w[:, None] * v[b, h, keep]).sum(0) / w.sum())
            heads.append(torch.stack(outs))
        rows.append(torch.stack(heads))
    return torch.stack(rows)


def _inputs(batch: int, mask_batch: int, seed: int) -> tuple[torch.Tensor, ...]:
    """float64 q (batch, 3, 5, 4), k and v (batch, 3, 6, 4) and a key mask with one key kept per row."""
    gen = torch.Generator().manual_seed(seed)
    q = torch.randn(batch, 3, 5, 4, generator=gen, dtype=torch.float64, requires_grad=True)
    k, v = (torch.randn(batch, 3, 6, 4, generator=gen, dtype=torch.float64, requires_grad=True) for _ in range(2))
    mask = torch.rand(mask_batch, 3, 1, 6, generator=gen) > 0.5
    mask[..., 0, int(torch.randint(6, (1,), generator=gen))] = True
    mask[0, 0, 0] = False
    mask[0, 0, 0, 2] = True  # a (row, head) that sees one key only
    return q, k, v, mask


@pytest.mark.parametrize(("batch", "mask_batch", "slice_scores"), [(7, 7, 2 * 3 * 5 * 6), (7, 1, 1), (4, 4, 10**6)])
def test_sliced_attention_equals_a_naive_loop_in_value_and_gradient(batch: int, mask_batch: int,
                                                                    slice_scores: int) -> None:
    """Slices of 2 rows (the last one short), of 1 row with a broadcast mask, and the whole batch at once."""
    q, k, v, mask = _inputs(batch, mask_batch, seed=batch + mask_batch)
    got = sliced_attention(q, k, v, mask, slice_scores=slice_scores)
    want = _naive(q, k, v, mask)
    torch.testing.assert_close(got, want, atol=1e-12, rtol=1e-10)
    g = torch.randn_like(want)
    for a, b in zip(torch.autograd.grad(got, (q, k, v), g), torch.autograd.grad(want, (q, k, v), g)):
        torch.testing.assert_close(a, b, atol=1e-12, rtol=1e-10)


def test_sliced_attention_on_strided_views_matches_sdpa_in_float32() -> None:
    """The fast block hands the kernel transposed views of (R, N, m, C) tokens; fp32 agrees with SDPA."""
    gen = torch.Generator().manual_seed(0)
    r, n, m, heads, d = 5, 32, 3, 4, 8
    x = torch.randn(r, n, m * heads * d, generator=gen, requires_grad=True)
    q, k, v = (t.view(r, n, m * heads, d).transpose(1, 2) for t in (x, x * 0.5, x.flip(1)))
    mask = torch.rand(r, m * heads, 1, n, generator=gen) > 0.3
    mask[..., 0] = True
    got = sliced_attention(q, k, v, mask, slice_scores=2 * m * heads * n * n)
    want = F.scaled_dot_product_attention(q, k, v, attn_mask=mask)
    torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-5)
    g = torch.randn_like(want)
    (grad_got,) = torch.autograd.grad(got, x, g, retain_graph=True)
    (grad_want,) = torch.autograd.grad(want, x, g)
    torch.testing.assert_close(grad_got, grad_want, atol=1e-4, rtol=1e-4)


def test_sliced_attention_in_bf16_autocast_stays_near_fp32() -> None:
    gen = torch.Generator().manual_seed(2)
    q, k, v = (torch.randn(6, 4, 24, 8, generator=gen) for _ in range(3))
    mask = torch.rand(6, 1, 1, 24, generator=gen) > 0.3
    mask[..., 0] = True
    want = sliced_attention(q, k, v, mask)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        got = sliced_attention(q.bfloat16(), k.bfloat16(), v.bfloat16(), mask)
    assert got.dtype == torch.bfloat16
    torch.testing.assert_close(got.float(), want, atol=3e-2, rtol=3e-2)


@pytest.mark.parametrize("keys", [8, SLICED_KEYS.start - 1, SLICED_KEYS.start, 32, SLICED_KEYS.stop - 1,
                                  SLICED_KEYS.stop, 96])
@pytest.mark.parametrize("grad", [False, True])
def test_attention_uses_the_sliced_kernel_only_in_a_cpu_render_within_its_key_range(keys: int, grad: bool) -> None:
    """Without a gradient (inputs that need none, or under no_grad) the sliced kernel runs within its key
    range; when a gradient flows, SDPA always does."""
    gen = torch.Generator().manual_seed(keys)
    q, k, v = (torch.randn(3, 4, keys, 8, generator=gen).requires_grad_(grad) for _ in range(3))
    mask = torch.rand(3, 1, 1, keys, generator=gen) > 0.3
    mask[..., 0] = True
    got = attention(q, k, v, mask)
    sliced = sliced_attention(q, k, v, mask)
    sdpa = F.scaled_dot_product_attention(q, k, v, attn_mask=mask)
    assert not torch.equal(sliced, sdpa)  # the two kernels round differently, so the choice is visible
    in_range = keys in SLICED_KEYS
    assert torch.equal(got, sliced if in_range and not grad else sdpa)
    with torch.no_grad():
        assert torch.equal(attention(q, k, v, mask), sliced if in_range else sdpa)
