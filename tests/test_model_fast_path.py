"""The fast implementation (``Runtime(impl="fast")``) computes what the reference path computes.

Independent references: ``F.grid_sample`` (align_corners=True, border padding) for the gathered
bilinear taps, and the same model run with ``impl="reference"`` (the implementation is an argument of the
call, the weights are shared) for outputs and parameter gradients of a training-mode render (stratified
samples from the same generator, a rig with one view facing away, so invalid projections and border
clamping occur).

Tolerances: float32 reordering of sums only, so outputs agree to 1e-5 absolute; each parameter's
gradient agrees to 1e-4 relative, plus 1e-6 of the largest gradient of the model absolute (some
gradients are zero in exact arithmetic, e.g. the bias of the view-weight net's last layer, whose
output is centred, and are pure rounding noise in both paths).
"""

from __future__ import annotations

import dataclasses

import pytest
import torch
import torch.nn.functional as F
from test_model_sray import FAR, H, K, NEAR, W, rig

from sray.model.config import SRayConfig
from sray.model.cra import STAGES, AttentionBlock
from sray.model.fast_field import block_forward
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel
from sray.model.source_gather import bilinear_taps, gather_bilinear, texel_table


@pytest.mark.parametrize("stride,hw_map", [(4, (8, 10)), (1, (32, 40)), (4, (1, 6))])
def test_gather_matches_grid_sample(stride: int, hw_map: tuple[int, int]) -> None:
    torch.manual_seed(0)
    h, w = hw_map
    maps = torch.randn(3, 5, h, w, requires_grad=True)
    # (m, R, N, 2) pixel coordinates from well outside to well inside the image (border clamping)
    uv = torch.rand(3, 7, 6, 2) * torch.tensor([stride * w * 1.6, stride * h * 1.6]) - torch.tensor(
        [stride * w * 0.3, stride * h * 0.3])
    scale = torch.tensor([2.0 / (stride * max(w - 1, 1)), 2.0 / (stride * max(h - 1, 1))])
    grid = (uv * scale - 1.0).clamp(-2.0, 2.0)
    ref = F.grid_sample(maps, grid, mode="bilinear", padding_mode="border", align_corners=True)  # (m, D, R, N)
    idx, wts = bilinear_taps(uv, 0, hw_map, stride)
    fast = gather_bilinear(texel_table(maps), idx, wts)  # (m, R, N, D)
    torch.testing.assert_close(fast, ref.permute(0, 2, 3, 1), atol=1e-5, rtol=1e-5)
    g = torch.randn_like(fast)
    (grad_ref,) = torch.autograd.grad(ref.permute(0, 2, 3, 1), maps, g)
    (grad_fast,) = torch.autograd.grad(fast, maps, g)
    torch.testing.assert_close(grad_fast, grad_ref, atol=1e-5, rtol=1e-5)


def _train_render(impl: str, fine_samples: str = "union") -> tuple[dict, dict[str, torch.Tensor]]:
    """Outputs and parameter gradients of one stratified render + a loss touching every output."""
    r = rig(m=4, facing_away=1)
    torch.manual_seed(0)
    net = SRayModel(SRayConfig(n_classes=5, n_coarse=8, n_fine=8, fine_samples=fine_samples))
    src = net.encode(r["rgb"], r["K"], r["c2w"])
    gen = torch.Generator().manual_seed(3)
    out = net.render_rays(src, r["origins"], r["dirs"], NEAR, FAR, stratified=True, generator=gen,
                          runtime=Runtime(impl=impl))
    loss = sum((out[p]["logits"].square().mean() + out[p]["rgb"].sum() + out[p]["depth"].sum())
               for p in ("coarse", "fine"))
    loss.backward()
    return out, {n: p.grad for n, p in net.named_parameters() if p.grad is not None}


@pytest.mark.parametrize("fine_samples", ["union", "new"])
def test_fast_equals_reference_outputs_and_gradients(fine_samples: str) -> None:
    out_ref, grad_ref = _train_render("reference", fine_samples)
    out_fast, grad_fast = _train_render("fast", fine_samples)
    for p in ("coarse", "fine"):
        for key in ("logits", "rgb", "depth", "opacity", "weights", "z"):
            torch.testing.assert_close(out_fast[p][key], out_ref[p][key], atol=1e-5, rtol=1e-5)
    assert grad_fast.keys() == grad_ref.keys() and len(grad_ref) > 100
    scale = max(float(g.abs().max()) for g in grad_ref.values())
    for name, g in grad_ref.items():
        torch.testing.assert_close(grad_fast[name], g, atol=1e-6 * scale, rtol=1e-4, msg=name)


def test_fast_equals_reference_without_gradient_at_forward_only_sliced_lengths() -> None:
    """A no-grad render at 40 samples per pass, where the intra-view stage runs the CPU's sliced attention
    kernel: the outputs still equal the reference path's."""
    r = rig(m=4, facing_away=1)
    torch.manual_seed(0)
    net = SRayModel(SRayConfig(n_classes=5, n_coarse=40, n_fine=40, fine_samples="new"))
    outs = {}
    with torch.no_grad():
        src = net.encode(r["rgb"], r["K"], r["c2w"])
        for impl in ("reference", "fast"):
            outs[impl] = net.render_rays(src, r["origins"], r["dirs"], NEAR, FAR, stratified=True,
                                         generator=torch.Generator().manual_seed(3), runtime=Runtime(impl=impl))
    for p in ("coarse", "fine"):
        for key in ("logits", "rgb", "depth", "weights"):
            torch.testing.assert_close(outs["fast"][p][key], outs["reference"][p][key], atol=1e-5, rtol=1e-5)


def test_fine_samples_new_evaluates_only_the_resampled_depths() -> None:
    out_union, _ = _train_render("fast", "union")
    out_new, _ = _train_render("fast", "new")
    assert out_union["fine"]["z"].shape[-1] == 16 and out_new["fine"]["z"].shape[-1] == 8
    # the same coarse pass, and the new depths are a subset of the union's
    torch.testing.assert_close(out_new["coarse"]["z"], out_union["coarse"]["z"])
    union = out_union["fine"]["z"]
    assert all(bool(torch.isin(out_new["fine"]["z"][i], union[i]).all()) for i in range(union.shape[0]))


@pytest.mark.parametrize("stage", ["intra", "cross", "dense"])
@pytest.mark.parametrize(("n", "m"), [(6, 5), (24, 3), (8, 4)])
def test_fast_attention_block_equals_the_reference_block(stage: str, n: int, m: int) -> None:
    """Each stage of the fast block, on (R, N, m, C) tokens, equals the reference block on its own grouping,
    in value and in gradient, with large random biases (q, k, v and projection), masked keys and fully
    masked sequences (where the block falls back to all keys). Without a gradient the sizes put the
    intra-view stage (24 keys) and the dense one (30 and 32 keys) on the CPU's sliced kernel: the values
    are compared there too."""
    torch.manual_seed(1)
    block = AttentionBlock(16, 4)
    with torch.no_grad():
        block.qkv.bias.normal_(0.0, 3.0)
        block.proj.bias.normal_(0.0, 3.0)
    r, c = 3, 16
    x = torch.randn(r, n, m, c, requires_grad=True)
    valid = torch.rand(r, n, m) > 0.3
    valid[0, :, 1] = False  # view 1 sees no sample of ray 0 (intra: all keys masked)
    valid[1, 2] = False  # sample 2 of ray 1 is seen by no view (cross: all keys masked)
    fast = block_forward(block, x, valid, stage)  # (R, N, m, C)
    grouped = STAGES[stage](block, x.transpose(1, 2), valid.transpose(1, 2)).transpose(1, 2)  # reference order
    torch.testing.assert_close(fast, grouped, atol=1e-5, rtol=1e-5)
    with torch.no_grad():
        torch.testing.assert_close(block_forward(block, x, valid, stage), grouped, atol=1e-5, rtol=1e-5)
    g = torch.randn_like(fast)
    grads_fast = torch.autograd.grad(fast, [x, *block.parameters()], g)
    grads_ref = torch.autograd.grad(grouped, [x, *block.parameters()], g)
    for got, want in zip(grads_fast, grads_ref):
        torch.testing.assert_close(got, want, atol=1e-4, rtol=1e-4)


def test_one_model_renders_a_whole_image_alike_with_either_implementation_passed_to_the_call() -> None:
    """``render_image`` of one model with ``Runtime(impl=...)`` as its argument: both implementations give the
    same image within float32 rounding, and the call changes nothing on the model (its config holds no
    implementation, no module keeps one)."""
    r = rig(m=3, facing_away=1)
    torch.manual_seed(0)
    net = SRayModel(SRayConfig(n_classes=5, n_coarse=8, n_fine=8)).eval()
    cfg = dataclasses.replace(net.cfg)
    with torch.no_grad():
        src = net.encode(r["rgb"], r["K"], r["c2w"])
        images = {impl: net.render_image(src, K, r["query"], (H, W), NEAR, FAR, Runtime(impl=impl, chunk=300))
                  for impl in ("reference", "fast")}
    for p in ("coarse", "fine"):
        for key in ("logits", "rgb", "depth", "opacity"):
            torch.testing.assert_close(images["fast"][p][key], images["reference"][p][key], atol=1e-5, rtol=1e-5)
    assert net.cfg == cfg and not hasattr(net.cfg, "impl")
    assert not any(hasattr(module, "impl") for module in net.modules())
