"""CONTRIBUTING.md, "Add an attention variant", performed: cross-view attention first, then intra-view.

The recipe is one entry in ``model/attention_variants.py`` (added here for the test's duration). The
new variant must run its stages in its order (checked against the blocks applied one by one with a
naive per-sequence loop), hold exactly its layers, and train inside the whole S-Ray model.
"""

from __future__ import annotations

import pytest
import torch
from test_model_attention import _naive_block

from sray.model.attention_variants import ATTENTION_VARIANTS
from sray.model.config import SRayConfig
from sray.model.cra import CrossReprojectionAttention
from sray.model.semantic_ray import SRayModel


@pytest.fixture
def cross_then_intra(monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setitem(ATTENTION_VARIANTS, "cross-intra", ("cross", "intra"))
    return "cross-intra"


def test_new_variant_runs_its_stages_in_its_order(cross_then_intra: str) -> None:
    torch.manual_seed(0)
    cfg = SRayConfig(attention=cross_then_intra, feat_dim=8, n_heads=2)
    module = CrossReprojectionAttention(cfg)
    assert {k.split(".")[0] for k in module.state_dict()} == {"depth_embedding", "cross", "intra"}
    r, m, n, c = 2, 3, 4, 8
    space = torch.randn(r, m, n, c)
    valid = torch.rand(r, m, n) > 0.3
    depth01 = torch.rand(r, n)
    got = module(space, valid, depth01)

    x = (space + module.position_signal(depth01)[:, None]).double()
    mid = torch.empty_like(x)
    for ray in range(r):  # cross-view first: over the m views of each (ray, sample)
        for k in range(n):
            mid[ray, :, k] = _naive_block(module.cross, x[ray, :, k], valid[ray, :, k])
    want = torch.empty_like(x)
    for ray in range(r):  # then intra-view: over the N samples of each (ray, view)
        for view in range(m):
            want[ray, view] = _naive_block(module.intra, mid[ray, view], valid[ray, view])
    torch.testing.assert_close(got.double(), want, rtol=1e-5, atol=1e-5)


def test_new_variant_trains_inside_the_model(cross_then_intra: str) -> None:
    torch.manual_seed(1)
    net = SRayModel(SRayConfig(attention=cross_then_intra, feat_dim=8, n_heads=2, n_coarse=4, n_fine=4,
                               n_classes=5, n_source=2))
    rgb = torch.rand(2, 3, 32, 32)
    K = torch.tensor([[30.0, 0, 15.5], [0, 30.0, 15.5], [0, 0, 1]]).expand(2, 3, 3)
    c2w = torch.eye(4).repeat(2, 1, 1)
    c2w[1, 0, 3] = 0.1
    src = net.encode(rgb, K, c2w)
    origins, dirs = torch.zeros(6, 3), torch.nn.functional.pad(torch.randn(6, 2) * 0.2, (0, 1), value=1.0)
    out = net.render_rays(src, origins, dirs, torch.full((6,), 0.5), torch.full((6,), 3.0), stratified=True)
    (out["coarse"]["logits"].sum() + out["fine"]["logits"].sum()).backward()
    for name in (f"{p}.attention.{stage}.qkv.weight" for p in ("coarse", "fine") for stage in ("cross", "intra")):
        grad = dict(net.named_parameters())[name].grad
        assert grad is not None and grad.abs().sum() > 0, name
    with pytest.raises(ValueError, match="cross-intra"):
        SRayConfig(attention="intra-cross")
