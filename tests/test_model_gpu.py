"""S-Ray on CUDA: agreement with the CPU result and finite fp16 / bf16 training steps, with either input setting
of the semantic-aware weight net."""

from __future__ import annotations

import pytest
import torch

from sray.model.config import SRayConfig
from sray.model.rays import pixel_rays
from sray.model.semantic_ray import SRayModel

pytestmark = pytest.mark.gpu
H, W = 48, 64


def _inputs(device: str) -> dict:
    gen = torch.Generator().manual_seed(0)
    K = torch.tensor([[40.0, 0.0, (W - 1) / 2], [0.0, 40.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
    c2w = torch.eye(4).repeat(4, 1, 1)
    c2w[:, 0, 3] = torch.linspace(-0.3, 0.3, 4)
    origins, dirs = pixel_rays(K, torch.eye(4), torch.rand(128, 2, generator=gen) * (W - 1))
    data = {"rgb": torch.rand(4, 3, H, W, generator=gen), "K": K.expand(4, 3, 3), "c2w": c2w,
            "origins": origins, "dirs": dirs}
    return {k: v.to(device) for k, v in data.items()}


def _net(device: str) -> SRayModel:
    torch.manual_seed(0)
    return SRayModel(SRayConfig(n_classes=6, n_coarse=16, n_fine=16)).to(device)


def test_cuda_matches_cpu_in_fp32() -> None:
    outs = []
    for device in ("cpu", "cuda"):
        net, x = _net(device).eval(), _inputs(device)
        with torch.no_grad():
            src = net.encode(x["rgb"], x["K"], x["c2w"])
            outs.append(net.render_rays(src, x["origins"], x["dirs"], 1.0, 5.0, stratified=False))
    for name in ("coarse", "fine"):
        for key in ("logits", "rgb", "depth", "opacity"):
            torch.testing.assert_close(outs[1][name][key].cpu(), outs[0][name][key], rtol=1e-3, atol=1e-3)


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_autocast_training_step_is_finite_on_cuda(dtype: torch.dtype) -> None:
    net, x = _net("cuda").train(), _inputs("cuda")
    with torch.autocast("cuda", dtype=dtype):
        src = net.encode(x["rgb"], x["K"], x["c2w"])
        out = net.render_rays(src, x["origins"], x["dirs"], 1.0, 5.0, stratified=True)
        loss = sum(out[p]["logits"].float().logsumexp(-1).mean() + out[p]["rgb"].float().mean()
                   for p in ("coarse", "fine"))
    loss.backward()
    assert torch.isfinite(loss)
    assert all(torch.isfinite(p.grad).all() for p in net.parameters() if p.grad is not None)
