"""Stage ``precision``: fp32 against bf16 (and fp16 on CUDA) in projection, a render, a step's loss and gradients."""

from __future__ import annotations

import torch

from sray.model.losses import render_loss
from sray.model.reprojection import project
from sray.model.source_set import rigid_inverse
from sray.platform.common.model_input import ray_batch
from sray.platform.train.step import PRECISIONS

from .context import CheckContext
from .report import StageResult
from .synthetic import model, pinhole, rig, training_sample

PROJECTION_TOL_PX = 0.01
ARGMAX_AGREEMENT = 0.99
"""Least share of confident pixels (fp32 top-2 logit margin > ``MARGIN``) whose label must agree."""
MARGIN = 0.1
LOSS_REL_TOL = 0.02
GRAD_COSINE = 0.85
"""Least cosine similarity of the gradient with fp32's (bf16 of a fresh model measured 0.92 on the CPU: the 19 encoder
layers accumulate rounding; a wrong geometry or a NaN gives far less)."""


def _autocast(ctx: CheckContext, precision: str) -> torch.autocast:
    dtype = PRECISIONS[precision]
    return torch.autocast(ctx.device.type, dtype=dtype, enabled=dtype is not None)


def projection_error(ctx: CheckContext, precision: str) -> float:
    """Max |uv_precision - uv_fp32| in pixels at 640 x 480, 90 degrees, over points 1-6 m in front of 4 cameras."""
    gen = torch.Generator().manual_seed(0)
    K = pinhole((480, 640), 90.0).expand(4, 3, 3).to(ctx.device)
    c2w = torch.eye(4).repeat(4, 1, 1)
    c2w[:, :3, 3] = torch.rand(4, 3, generator=gen) * 2 - 1
    w2c = rigid_inverse(c2w.to(ctx.device))
    points = (torch.rand(2048, 3, generator=gen) * torch.tensor([4.0, 3.0, 5.0]) + torch.tensor([-2.0, -1.5, 1.0]))
    points = points.to(ctx.device) + c2w[0, :3, 3].to(ctx.device)
    ref, depth = project(points, K, w2c)
    with _autocast(ctx, precision):
        got, _ = project(points, K, w2c)
    seen = (depth > 0.5) & (ref.abs().amax(-1) < 2000)
    return float((got - ref).abs().amax(-1)[seen].max())


def argmax_agreement(ctx: CheckContext, precision: str) -> tuple[float, int]:
    """Share of confident pixels with the same label under ``precision`` as under fp32, and their count."""
    net = model(ctx.samples, ctx.views, ctx.device).eval()
    sources, query = rig(ctx.views, ctx.image_hw, ctx.device)
    images = []
    for p in ("no", precision):
        with torch.no_grad(), _autocast(ctx, p):
            src = net.encode(sources.rgb, sources.K, sources.c2w, sources.depth)
            images.append(net.render_image(src, query.K, query.c2w, ctx.image_hw, 1.0, 5.0)
                          ["fine"]["logits"].float())
    top2 = images[0].topk(2, dim=-1).values
    confident = (top2[..., 0] - top2[..., 1]) > MARGIN
    same = images[0].argmax(-1) == images[1].argmax(-1)
    n = int(confident.sum())
    return (float(same[confident].float().mean()) if n else 1.0), n


def step_agreement(ctx: CheckContext, precision: str) -> tuple[float, float]:
    """(relative loss difference, gradient cosine similarity) of one training step against fp32."""
    results = []
    for p in ("no", precision):
        net = model(ctx.samples, ctx.views, ctx.device).train()
        sample = training_sample(ctx.views, ctx.image_hw, ctx.rays, net.cfg.n_classes, ctx.device)
        batch = ray_batch(sample)
        torch.manual_seed(1)
        origins, dirs, near, far = batch.query.rays()
        with _autocast(ctx, p):
            src = net.encode(batch.src_rgb, batch.src_K, batch.src_c2w, batch.src_depth)
            out = net.render_rays(src, origins, dirs, near, far, stratified=True)
        loss, _ = render_loss(out, sample.target_label, sample.target_rgb, net.cfg)
        loss.backward()
        grads = torch.cat([q.grad.flatten().float() for q in net.parameters() if q.grad is not None])
        results.append((float(loss.detach()), grads))
    (loss32, g32), (loss_lp, g_lp) = results
    cosine = float(torch.nn.functional.cosine_similarity(g32, g_lp, dim=0))
    return abs(loss_lp - loss32) / max(abs(loss32), 1e-12), cosine


def run(ctx: CheckContext) -> StageResult:
    """Every agreement check for every low precision of this device."""
    rows, failures = [], []
    for precision in ctx.low_precisions():
        px = projection_error(ctx, precision)
        agree, n = argmax_agreement(ctx, precision)
        loss_rel, cosine = step_agreement(ctx, precision)
        checks = [("projection", f"{px:.4f} px", px <= PROJECTION_TOL_PX, f"<= {PROJECTION_TOL_PX} px"),
                  ("render argmax", f"{100 * agree:.2f} % of {n} confident px", agree >= ARGMAX_AGREEMENT,
                   f">= {100 * ARGMAX_AGREEMENT:.0f} %"),
                  ("step loss", f"{loss_rel:.2e} relative", loss_rel <= LOSS_REL_TOL, f"<= {LOSS_REL_TOL}"),
                  ("step gradient", f"cosine {cosine:.4f}", cosine >= GRAD_COSINE, f">= {GRAD_COSINE}")]
        rows += [[precision, name, value, tol, "ok" if ok else "FAIL"] for name, value, ok, tol in checks]
        failures += [f"{precision} {name} {value}" for name, value, ok, _ in checks if not ok]
    summary = ("all within tolerance" if not failures else "outside tolerance: " + "; ".join(failures))
    return StageResult("failed" if failures else "passed", summary,
                       header=["precision", "check", "measured", "tolerance", "verdict"], rows=rows)
