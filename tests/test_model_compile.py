"""The per-sample S-Ray network captures as one torch.compile graph and matches eager mode (with either input
setting of the semantic-aware weight net)."""

from __future__ import annotations

import pytest
import torch

from sray.model.config import SRayConfig
from sray.model.rays import pixel_rays
from sray.model.semantic_ray import SRayModel

H, W = 32, 32


def _setup() -> tuple[SRayModel, object, torch.Tensor, torch.Tensor, torch.Tensor]:
    torch.manual_seed(0)
    net = SRayModel(SRayConfig(n_classes=4, n_coarse=6, n_fine=6))
    K = torch.tensor([[28.0, 0.0, (W - 1) / 2], [0.0, 28.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
    c2w = torch.eye(4).repeat(2, 1, 1)
    c2w[:, 0, 3] = torch.tensor([-0.2, 0.2])
    src = net.encode(torch.rand(2, 3, H, W), K.expand(2, 3, 3), c2w)
    origins, dirs = pixel_rays(K, torch.eye(4), torch.rand(10, 2) * (W - 1))
    z = torch.linspace(1.0, 4.0, 6).expand(10, 6)
    return net, src, origins, dirs, z


def _outputs_and_grads(fn, net: SRayModel, src, origins, dirs, z) -> tuple[dict, list[torch.Tensor]]:
    net.zero_grad()
    out = fn(src, origins, dirs, z, torch.full((10,), 1.0), torch.full((10,), 4.0), "fast")
    (out["sigma"].sum() + out["logits"].square().sum() + out["rgb"].sum()).backward(retain_graph=True)
    return out, [p.grad.clone() for p in net.coarse.parameters()]


def test_field_compiles_as_one_graph_forward_and_backward() -> None:
    net, src, origins, dirs, z = _setup()
    compiled = torch.compile(net.coarse, fullgraph=True, backend="aot_eager")
    ref, ref_grads = _outputs_and_grads(net.coarse, net, src, origins, dirs, z)
    got, got_grads = _outputs_and_grads(compiled, net, src, origins, dirs, z)
    for k in ref:
        torch.testing.assert_close(got[k], ref[k], rtol=1e-5, atol=1e-6)
    for g, r in zip(got_grads, ref_grads):
        torch.testing.assert_close(g, r, rtol=1e-4, atol=1e-6)


@pytest.mark.slow
def test_render_rays_under_inductor_matches_eager() -> None:
    net, src, origins, dirs, _ = _setup()
    net.eval()
    compiled = torch.compile(net.render_rays)
    with torch.no_grad():
        got = compiled(src, origins, dirs, 1.0, 4.0, stratified=False)
        ref = net.render_rays(src, origins, dirs, 1.0, 4.0, stratified=False)
    for name in ("coarse", "fine"):
        for k in ref[name]:
            torch.testing.assert_close(got[name][k], ref[name][k], rtol=1e-4, atol=1e-5)
