"""A training loss computed in pieces of rays (``model/piecewise_loss.py``) is the whole batch's loss.

Independent reference: the batch rendered at once and ``render_loss`` over all of it, differentiated
by one ordinary ``backward``. Sampling is made deterministic (the network's ``render_rays`` is wrapped
to ignore ``stratified``) so both see the same depths. Tolerance: float32 reordering of sums only
(loss and terms to 1e-6 relative; each parameter's gradient to 1e-4 relative plus 1e-6 of the model's
largest gradient absolute, as tests/test_model_fast_path.py).
"""

from __future__ import annotations

import pytest
import torch
from test_model_sray import FAR, NEAR, rig

from sray.model.config import SRayConfig
from sray.model.losses import render_loss
from sray.model.ray_chunks import CPU_RAYS, CUDA_RENDER_RAYS, render_chunk_rays, train_piece_rays
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SourceSet, SRayModel

N_CLASSES = 5


def _net(**kw) -> SRayModel:
    """A seeded small network whose renders are deterministic whatever ``stratified`` asks."""
    torch.manual_seed(0)
    net = SRayModel(SRayConfig(n_classes=N_CLASSES, n_coarse=6, n_fine=6, **kw))
    plain = net.render_rays

    def deterministic(src: SourceSet, o: torch.Tensor, d: torch.Tensor, near: torch.Tensor | float,
                      far: torch.Tensor | float, stratified: bool, generator: torch.Generator | None = None,
                      runtime: Runtime = Runtime()) -> dict[str, dict[str, torch.Tensor]]:
        return plain(src, o, d, near, far, stratified=False, runtime=runtime)

    net.render_rays = deterministic  # type: ignore[method-assign]
    return net


def _targets(n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Labels with unlabelled rays (the whole second piece of 5 among them) and colours."""
    gen = torch.Generator().manual_seed(1)
    label = torch.randint(0, N_CLASSES, (n,), generator=gen)
    label[5:10] = 255
    label[17] = 255
    return label, torch.rand(n, 3, generator=gen)


def _loss_and_grads(net: SRayModel, piece: int, scale: float = 1.0,
                    frozen_encoder: bool = False) -> tuple[torch.Tensor, dict, dict[str, torch.Tensor]]:
    """Loss, terms and parameter gradients of the rig's batch: ``training_loss`` in pieces of ``piece`` rays, or
    with ``piece`` 0 the reference, the batch rendered at once and ``render_loss`` over all of it."""
    r = rig(m=3, facing_away=1)
    n = r["origins"].shape[0]
    label, rgb = _targets(n)
    near = torch.full((n,), NEAR)  # (R,) bounds: the pieces slice them
    with torch.no_grad() if frozen_encoder else torch.enable_grad():
        src = net.encode(r["rgb"], r["K"], r["c2w"])
    if piece:
        loss, terms = net.training_loss(src, r["origins"], r["dirs"], near, FAR, label, rgb, Runtime(train_piece=piece))
    else:
        out = net.render_rays(src, r["origins"], r["dirs"], near, FAR, stratified=True)
        loss, terms = render_loss(out, label, rgb, net.cfg)
    (loss * scale).backward()
    return loss.detach(), terms, {n: p.grad for n, p in net.named_parameters() if p.grad is not None}


def _assert_grads_close(got: dict[str, torch.Tensor], want: dict[str, torch.Tensor]) -> None:
    assert set(got) == set(want)
    largest = max(g.abs().max() for g in want.values())
    for name, g in want.items():
        torch.testing.assert_close(got[name], g, rtol=1e-4, atol=1e-6 * float(largest), msg=name)


@pytest.mark.parametrize("class_weights", [(), (1.0, 2.0, 0.5, 3.0, 1.5)])
@pytest.mark.parametrize("fine_samples", ["union", "new"])
def test_pieces_give_the_whole_batch_loss_terms_and_gradients(class_weights: tuple, fine_samples: str) -> None:
    kw = {"class_weights": class_weights, "fine_samples": fine_samples}
    loss_w, terms_w, grads_w = _loss_and_grads(_net(**kw), piece=0)
    loss_p, terms_p, grads_p = _loss_and_grads(_net(**kw), piece=5)  # 24 rays: pieces of 5, 5, 5, 5, 4
    torch.testing.assert_close(loss_p, loss_w, rtol=1e-6, atol=0)
    assert set(terms_p) == set(terms_w)
    for key in terms_w:
        torch.testing.assert_close(terms_p[key].float(), terms_w[key].float(), rtol=1e-6, atol=1e-7, msg=key)
    assert any(name.startswith("encoder.") for name in grads_w)  # the encoder's gradient arrives too
    _assert_grads_close(grads_p, grads_w)


def test_a_scaled_backward_scales_every_gradient() -> None:
    """A loss scaler multiplies the loss before ``backward``: the gathered gradients follow it."""
    _, _, grads_1 = _loss_and_grads(_net(), piece=7)
    _, _, grads_8 = _loss_and_grads(_net(), piece=7, scale=8.0)
    _assert_grads_close({k: g / 8.0 for k, g in grads_8.items()}, grads_1)


def test_frozen_modules_get_no_gradient_and_the_rest_match() -> None:
    """Finetuning: sources encoded without grad, only some modules trainable."""
    nets = [_net(), _net()]
    for net in nets:
        for name, p in net.named_parameters():
            p.requires_grad_(name.startswith("fine."))
    _, _, grads_w = _loss_and_grads(nets[0], piece=0, frozen_encoder=True)
    _, _, grads_p = _loss_and_grads(nets[1], piece=4, frozen_encoder=True)
    assert grads_w and all(name.startswith("fine.") for name in grads_p)
    _assert_grads_close(grads_p, grads_w)


def test_without_grad_mode_the_loss_is_the_same_and_nothing_is_kept() -> None:
    r = rig(m=3)
    label, rgb = _targets(r["origins"].shape[0])
    losses = []
    for piece in (0, 5):
        net = _net()
        with torch.no_grad():
            src = net.encode(r["rgb"], r["K"], r["c2w"])
            if piece:
                loss, _ = net.training_loss(src, r["origins"], r["dirs"], NEAR, FAR, label, rgb,
                                            Runtime(train_piece=piece))
            else:
                loss, _ = render_loss(net.render_rays(src, r["origins"], r["dirs"], NEAR, FAR, True), label, rgb,
                                      net.cfg)
        assert not loss.requires_grad
        losses.append(loss)
    torch.testing.assert_close(losses[1], losses[0], rtol=1e-6, atol=0)


def test_one_piece_is_the_ordinary_pass() -> None:
    """With a piece as large as the batch, ``training_loss`` is render + ``render_loss``, bit for bit."""
    r = rig(m=3)
    label, rgb = _targets(r["origins"].shape[0])
    torch.manual_seed(0)
    net = SRayModel(SRayConfig(n_classes=N_CLASSES, n_coarse=6, n_fine=6))
    src = net.encode(r["rgb"], r["K"], r["c2w"])
    torch.manual_seed(5)
    got, _ = net.training_loss(src, r["origins"], r["dirs"], NEAR, FAR, label, rgb, Runtime(train_piece=24))
    torch.manual_seed(5)
    want, _ = render_loss(net.render_rays(src, r["origins"], r["dirs"], NEAR, FAR, stratified=True), label, rgb,
                          net.cfg)
    assert torch.equal(got, want)


def test_ray_counts_by_device() -> None:
    cpu, cuda = torch.device("cpu"), torch.device("cuda")
    assert render_chunk_rays(0, cpu) == CPU_RAYS and render_chunk_rays(0, cuda) == CUDA_RENDER_RAYS
    assert render_chunk_rays(300, cpu) == 300 == render_chunk_rays(300, cuda)
    assert train_piece_rays(0, cpu, 1024) == CPU_RAYS and train_piece_rays(0, cuda, 1024) == 1024
    assert train_piece_rays(0, cpu, 100) == 100 and train_piece_rays(64, cuda, 1024) == 64
    with pytest.raises(ValueError, match="0 for the device's default"):
        render_chunk_rays(-1, cpu)
    with pytest.raises(ValueError, match="train_piece"):
        Runtime(train_piece=-4)
