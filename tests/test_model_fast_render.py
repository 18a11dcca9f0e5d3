"""The fast render mode is the documented approximation: each of its savings checked against an independent path.

* with every ray sent to the fine pass, its rays equal the full renderer's with ``fine_samples="new"``
  (same deterministic coarse samples, same inverse-CDF depths), to float32 rounding;
* with no ray sent (confidence 0), the fine result is the coarse pass of the full renderer;
* a mixed threshold gives, ray by ray, one of those two results;
* the bilinear upsampling reproduces a linear ramp exactly inside the rendered grid.
"""

from __future__ import annotations

import torch
from test_model_sray import FAR, NEAR, rig

from sray.model.config import SRayConfig
from sray.model.fast_render import FAST_KEYS, upsample_to
from sray.model.semantic_ray import SRayModel


def _setup(fine_samples: str) -> tuple[SRayModel, dict, object]:
    r = rig(m=4, facing_away=1)
    torch.manual_seed(0)
    net = SRayModel(SRayConfig(n_classes=5, n_coarse=8, n_fine=8, fine_samples=fine_samples)).eval()
    return net, r, net.encode(r["rgb"], r["K"], r["c2w"])


@torch.no_grad()
def test_all_rays_fine_equals_full_render_with_new_samples() -> None:
    net, r, src = _setup("new")
    full = net.render_rays(src, r["origins"], r["dirs"], NEAR, FAR, stratified=False)
    fast = net.render_rays_fast(src, r["origins"], r["dirs"], NEAR, FAR, confidence=2.0)
    for p in ("coarse", "fine"):
        for k in FAST_KEYS:
            torch.testing.assert_close(fast[p][k], full[p][k], atol=1e-5, rtol=1e-5)


@torch.no_grad()
def test_confident_rays_keep_their_coarse_result() -> None:
    net, r, src = _setup("new")
    full = net.render_rays(src, r["origins"], r["dirs"], NEAR, FAR, stratified=False)
    none = net.render_rays_fast(src, r["origins"], r["dirs"], NEAR, FAR, confidence=0.0)
    for k in FAST_KEYS:
        torch.testing.assert_close(none["fine"][k], full["coarse"][k], atol=1e-5, rtol=1e-5)
    conf = torch.softmax(full["coarse"]["logits"], -1).amax(-1)
    threshold = float(conf.median())
    mixed = net.render_rays_fast(src, r["origins"], r["dirs"], NEAR, FAR, confidence=threshold)
    unsure = conf < threshold
    assert 0 < int(unsure.sum()) < unsure.numel()
    for k in FAST_KEYS:
        want = torch.where(unsure.view(-1, *[1] * (full["fine"][k].ndim - 1)), full["fine"][k], full["coarse"][k])
        torch.testing.assert_close(mixed["fine"][k], want, atol=1e-5, rtol=1e-5)


def test_upsampling_reproduces_a_linear_ramp() -> None:
    h, w, s = 24, 32, 4
    vs = torch.arange(s // 2, h, s, dtype=torch.float32)
    us = torch.arange(s // 2, w, s, dtype=torch.float32)
    gv, gu = torch.meshgrid(vs, us, indexing="ij")
    values = torch.stack([2 * gu + 3 * gv, -gu], dim=-1)  # (h', w', 2), linear in (u, v)
    v, u = torch.meshgrid(torch.arange(float(s // 2), float(vs[-1]) + 1),
                          torch.arange(float(s // 2), float(us[-1]) + 1),
                          indexing="ij")
    uv = torch.stack([u.reshape(-1), v.reshape(-1)], dim=-1)  # every pixel inside the rendered grid
    out = upsample_to(values, (len(vs), len(us)), s, uv)
    torch.testing.assert_close(out, torch.stack([2 * uv[:, 0] + 3 * uv[:, 1], -uv[:, 0]], dim=-1), atol=1e-4, rtol=1e-5)
