"""``sray bench profile --workload kernels train-kernels chunks attention-keys``: the CPU attention options at the
render's and training step's shapes, a render per chunk size (whether a chunk's tokens stay in cache), and SDPA's
flash kernel against ``sliced_attention`` by key length (rerun on another CPU before trusting docs/performance.md)."""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F
from torch import Tensor
from torch.nn.attention import SDPBackend, sdpa_kernel

from sray.jobs.bench.probes import model_config, synthetic_batch, time_call
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel
from sray.model.sliced_attention import SLICED_KEYS, sliced_attention

HEADS, HEAD_DIM, VIEWS = 4, 8, 8
"""The default model's attention: 4 heads of 8 channels, over 8 source views."""
MATERIALISING = ("SDPA math backend", "matmul + softmax")
"""Kernels that build the whole (L, L) score matrix: skipped forward + backward at the intra-view stage, where the
forward table already shows them 8-11x slower than SDPA's flash kernel."""
CPU = torch.device("cpu")


def _flash(q: Tensor, k: Tensor, v: Tensor, mask: Tensor) -> Tensor:
    """SDPA (its flash kernel on a CPU) with a boolean key mask."""
    return F.scaled_dot_product_attention(q, k, v, attn_mask=mask)


def _kernels(q: Tensor, k: Tensor, v: Tensor, mask: Tensor) -> dict[str, Callable[[], Tensor]]:
    """The attention implementations compared, each a closure over the same inputs."""
    additive = torch.zeros(mask.shape).masked_fill(~mask, float("-inf"))

    def math() -> Tensor:
        with sdpa_kernel(SDPBackend.MATH):
            return _flash(q, k, v, mask)

    def explicit() -> Tensor:
        scores = (q @ k.transpose(-1, -2)) * q.shape[-1] ** -0.5
        return torch.softmax(scores.masked_fill(~mask, float("-inf")), dim=-1) @ v

    return {"SDPA flash, boolean mask": lambda: _flash(q, k, v, mask),
            "SDPA flash, additive mask": lambda: F.scaled_dot_product_attention(q, k, v, attn_mask=additive),
            "SDPA math backend": math, "matmul + softmax": explicit,
            "matmul + softmax in cache-sized slices (sray's CPU kernel)": lambda: sliced_attention(q, k, v, mask)}


def with_backward(fn: Callable[[], Tensor], inputs: tuple[Tensor, ...]) -> Callable[[], Tensor]:
    """``fn`` and the backward of a dense random gradient (as a training step's; ``out.sum()``'s is stride-0)."""
    upstream = torch.randn(fn().shape, generator=torch.Generator().manual_seed(1))

    def call() -> Tensor:
        out = fn()
        torch.autograd.grad(out, inputs, upstream)
        return out
    return call


def kernel_table(rays: int, samples: int, repeats: int = 2, backward: bool = False) -> str:
    """Seconds per call and GFLOP/s of each implementation at the intra-view (per ray and view, over ``samples``) and
    cross-view stage (per ray and sample, over the views); ``backward``: forward + backward, 3x the forward's FLOPs."""
    gen = torch.Generator().manual_seed(0)
    shapes = {"intra-view": (rays, VIEWS * HEADS, samples), "cross-view": (rays * samples, HEADS, VIEWS)}
    lines = ["| stage | q, k, v shape | implementation | s / call | GFLOP/s | max abs diff to the first |",
             "|---|---|---|---:|---:|---:|"]
    for stage, (batch, heads, length) in shapes.items():
        q, k, v = (torch.randn(batch, heads, length, HEAD_DIM, generator=gen).requires_grad_(backward)
                   for _ in range(3))
        mask = torch.rand(batch, 1, 1, length, generator=gen) > 0.2
        mask[..., 0] = True  # every query keeps a key, as the model's key masks guarantee
        flops = 4 * batch * heads * length * length * HEAD_DIM * (3 if backward else 1)
        first = None
        with torch.set_grad_enabled(backward):
            for name, fn in _kernels(q, k, v, mask).items():
                if backward and stage == "intra-view" and name in MATERIALISING:
                    continue  # minutes per call: they store every (L, L) score matrix for the backward
                seconds = time_call(with_backward(fn, (q, k, v)) if backward else fn, CPU, repeats)
                out = fn().detach()
                first = out if first is None else first
                lines.append(f"| {stage} | {tuple(q.shape)} | {name} | {seconds:.3f} | {flops / seconds / 1e9:.1f} | "
                             f"{(out - first).abs().max().item():.1e} |")
    return "\n".join(lines)


def chunk_table(chunks: tuple[int, ...], impl: str, crop: tuple[int, int] = (60, 80), samples: int = 24,
                repeats: int = 2) -> str:
    """Seconds to render a ``crop`` (h, w) of the 320x240 view at each chunk size, and the whole view's estimate."""
    torch.manual_seed(0)
    model = SRayModel(model_config({"coarse": samples, "fine": samples, "views": VIEWS})).eval()
    batch = synthetic_batch(1, VIEWS, (240, 320), CPU)
    with torch.no_grad():
        src = model.encode(batch["src_rgb"], batch["src_K"], batch["src_c2w"])
    h, w = crop
    K = batch["K"].clone()
    K[0] *= w / 320
    K[1] *= h / 240
    n_rays, scale = h * w, 320 * 240 / (h * w)
    lines = [f"| impl | chunk (rays) | token tensor per chunk (MB) | s for {n_rays} rays | s per 320x240 view "
             f"(x{scale:g}) |", "|---|---:|---:|---:|---:|"]
    for chunk in chunks:
        def render() -> None:
            with torch.no_grad():
                model.render_image(src, K, torch.eye(4), crop, 1.0, 5.0, Runtime(impl=impl, chunk=chunk))
        seconds = time_call(render, CPU, repeats)
        mb = min(chunk, n_rays) * 3 * samples * VIEWS * model.cfg.feat_dim * 4 / 2**20
        lines.append(f"| {impl} | {chunk} | {mb:.0f} | {seconds:.2f} | {scale * seconds:.0f} |")
    return "\n".join(lines)


def _stage_seconds(kernel: Callable[..., Tensor], rays: int, samples: int, views: int, grad: bool,
                   repeats: int) -> float:
    """Median seconds of the intra-view stage as the fast block runs it: q, k and v three linears of (R, N, m, C)
    tokens, viewed as (R, m * heads, N, d), then ``kernel`` with one key kept per query; with ``grad``, the backward
    of a dense upstream gradient to the tokens and the weight."""
    gen = torch.Generator().manual_seed(samples)
    c = HEADS * HEAD_DIM
    tokens = torch.randn(rays, samples, views, c, generator=gen).requires_grad_(grad)
    weight = (torch.randn(3 * c, c, generator=gen) * c ** -0.5).requires_grad_(grad)
    mask = torch.rand(rays, views * HEADS, 1, samples, generator=gen) > 0.2
    mask[..., 0] = True

    def stage() -> Tensor:
        q, k, v = (F.linear(tokens, weight[i * c:(i + 1) * c]).view(rays, samples, views * HEADS, HEAD_DIM)
                   .transpose(1, 2) for i in range(3))
        return kernel(q, k, v, mask)

    if grad:
        return time_call(with_backward(stage, (tokens, weight)), CPU, repeats)
    with torch.no_grad():
        return time_call(stage, CPU, repeats)


def key_length_table(samples: tuple[int, ...], rays: int = 256, views: int = 8, repeats: int = 3) -> str:
    """Milliseconds per intra-view stage, flash against sliced, per sample count and pass; the kernel used there."""
    lines = ["| samples (keys) | pass | SDPA flash ms | sliced ms | flash / sliced | kernel used on a CPU |",
             "|---:|---|---:|---:|---:|---|"]
    for n in samples:
        for grad in (False, True):
            used = "sliced" if n in SLICED_KEYS and not grad else "SDPA flash"
            t_flash = _stage_seconds(_flash, rays, n, views, grad, repeats)
            t_sliced = _stage_seconds(sliced_attention, rays, n, views, grad, repeats)
            lines.append(f"| {n} | {'forward + backward' if grad else 'forward'} | {1e3 * t_flash:.3g} | "
                         f"{1e3 * t_sliced:.3g} | {t_flash / t_sliced:.2f} | {used} |")
    return "\n".join(lines)
