"""``sray bench profile --workload kernels chunks``: two levers the render profile points at, timed.

* ``kernels``: the attention call that dominates the render profile, at the render's own shapes
  (a chunk of 4096 rays, 24 + 48 samples seen by the fine pass, 8 source views, 4 heads of 8
  channels), with each CPU option torch offers: SDPA's flash kernel with a boolean or an additive
  mask, SDPA's math backend, an explicit matmul + softmax, and that done a cache-sized slice of rays at
  a time (``model.sliced_attention``, the fast path's kernel at 24 to 64 keys on a CPU). All compute the same attention
  (the table gives their largest difference to the first). ``train-kernels`` times the same options
  forward + backward at one pass of the paper-config training step (1024 rays, 64 samples);
* ``chunks``: a whole-image render of a small crop (80x60 rays with the 320x240 camera's field of
  view) at several chunk sizes, since a chunk's token tensors (rays x samples x views x channels) decide whether
  they stay in cache and whether glibc serves them from its heap or maps fresh pages.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F
from torch import Tensor
from torch.nn.attention import SDPBackend, sdpa_kernel

from sray.jobs.bench.probes import time_call
from sray.jobs.bench.workloads import model_config, synthetic_batch
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel
from sray.model.sliced_attention import sliced_attention

HEADS, HEAD_DIM, VIEWS = 4, 8, 8
"""The default model's attention: 4 heads of 8 channels, over 8 source views."""


MATERIALISING = ("SDPA math backend", "matmul + softmax")
"""The implementations that build the whole (L, L) score matrix; skipped forward + backward at the
intra-view stage, where the forward table already shows them 8-11x slower than SDPA's flash kernel."""


def _explicit(q: Tensor, k: Tensor, v: Tensor, mask: Tensor) -> Tensor:
    """softmax(q k^T / sqrt(d), masked) v with plain matmuls."""
    scores = (q @ k.transpose(-1, -2)) * q.shape[-1] ** -0.5
    return torch.softmax(scores.masked_fill(~mask, float("-inf")), dim=-1) @ v


def _kernels(q: Tensor, k: Tensor, v: Tensor, mask: Tensor) -> dict[str, Callable[[], Tensor]]:
    """The attention implementations compared, each a closure over the same inputs."""
    additive = torch.zeros(mask.shape).masked_fill(~mask, float("-inf"))

    def math() -> Tensor:
        with sdpa_kernel(SDPBackend.MATH):
            return F.scaled_dot_product_attention(q, k, v, attn_mask=mask)

    return {"SDPA flash, boolean mask": lambda: F.scaled_dot_product_attention(q, k, v, attn_mask=mask),
            "SDPA flash, additive mask": lambda: F.scaled_dot_product_attention(q, k, v, attn_mask=additive),
            "SDPA math backend": math,
            "matmul + softmax": lambda: _explicit(q, k, v, mask),
            "matmul + softmax in cache-sized slices (sray's CPU kernel)": lambda: sliced_attention(q, k, v, mask)}


def kernel_table(rays: int, samples: int, repeats: int = 2, backward: bool = False) -> str:
    """Seconds per call and GFLOP/s of each implementation for the intra-view stage (per ray and view,
    over ``samples``) and the cross-view stage (per ray and sample, over the views).

    ``backward``: time forward + backward (a dense random gradient of the output to q, k and v),
    as in a training step, and count the backward's matmuls too (3x the forward's)."""
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
                call = with_backward(fn, (q, k, v)) if backward else fn
                seconds = time_call(call, torch.device("cpu"), repeats)
                out = fn().detach()
                first = out if first is None else first
                lines.append(f"| {stage} | {tuple(q.shape)} | {name} | {seconds:.3f} | {flops / seconds / 1e9:.1f} | "
                             f"{(out - first).abs().max().item():.1e} |")
    return "\n".join(lines)


def with_backward(fn: Callable[[], Tensor], inputs: tuple[Tensor, ...]) -> Callable[[], Tensor]:
    """``fn`` followed by the backward pass of a dense random gradient of its output to ``inputs``
    (gradients discarded). Dense as in a training step: the gradient of ``out.sum()`` is a stride-0
    tensor, which sends batched matmuls down a per-matrix path that inflates the materialising kernels."""
    upstream = torch.randn(fn().shape, generator=torch.Generator().manual_seed(1))

    def call() -> Tensor:
        out = fn()
        torch.autograd.grad(out, inputs, upstream)
        return out
    return call


def chunk_table(chunks: tuple[int, ...], impl: str, crop: tuple[int, int] = (60, 80), samples: int = 24,
                repeats: int = 2) -> str:
    """Seconds to render a ``crop`` (h, w) of the 320x240 view (the same field of view, fewer rays) with
    ``samples`` + ``samples`` samples at each chunk size, and the whole view's seconds extrapolated."""
    torch.manual_seed(0)
    model = SRayModel(model_config({"coarse": samples, "fine": samples, "views": VIEWS})).eval()
    batch = synthetic_batch(1, VIEWS, (240, 320), torch.device("cpu"))
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
        seconds = time_call(render, torch.device("cpu"), repeats)
        mb = min(chunk, n_rays) * 3 * samples * VIEWS * model.cfg.feat_dim * 4 / 2**20
        lines.append(f"| {impl} | {chunk} | {mb:.0f} | {seconds:.2f} | {scale * seconds:.0f} |")
    return "\n".join(lines)
