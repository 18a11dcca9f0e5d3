"""render_loss against a hand-written cross-entropy and MSE."""

from __future__ import annotations

import math

import pytest
import torch
from loss_settings import LossConfig

from sray.model.losses import render_loss

IGNORE = 255


def _out(n_rays: int, n_classes: int, seed: int = 0, grad: bool = True) -> dict:
    g = torch.Generator().manual_seed(seed)
    return {
        name: {
            "logits": torch.randn(n_rays, n_classes, generator=g).requires_grad_(grad),
            "rgb": torch.rand(n_rays, 3, generator=g).requires_grad_(grad),
        }
        for name in ("coarse", "fine")
    }


def _manual_ce(logits: torch.Tensor, target: torch.Tensor) -> float:
    """Mean of -log softmax(logits)[target] over labelled rays, one ray at a time."""
    losses = []
    for row, t in zip(logits.tolist(), target.tolist(), strict=True):
        if t == IGNORE:
            continue
        log_norm = math.log(sum(math.exp(v) for v in row))
        losses.append(log_norm - row[t])
    return sum(losses) / len(losses)


def test_loss_matches_manual_cross_entropy_over_labelled_rays_and_mse() -> None:
    out = _out(12, 5)
    target = torch.tensor([0, 4, IGNORE, 2, 2, IGNORE, 1, 3, IGNORE, 0, 4, 1])
    rgb = torch.rand(12, 3, generator=torch.Generator().manual_seed(9))
    cfg = LossConfig(lambda_sem=0.5, lambda_rgb=2.0, ignore_id=IGNORE)
    total, terms = render_loss(out, target, rgb, cfg)
    sem = {p: _manual_ce(out[p]["logits"].detach(), target) for p in ("coarse", "fine")}
    mse = {p: float(((out[p]["rgb"].detach() - rgb) ** 2).mean()) for p in ("coarse", "fine")}
    for p in ("coarse", "fine"):
        assert math.isclose(float(terms[f"sem_{p}"]), sem[p], rel_tol=1e-5)
        assert math.isclose(float(terms[f"rgb_{p}"]), mse[p], rel_tol=1e-5)
    expected = 0.5 * (sem["coarse"] + sem["fine"]) + 2.0 * (mse["coarse"] + mse["fine"])
    assert math.isclose(float(total.detach()), expected, rel_tol=1e-5)
    assert int(terms["n_labelled"]) == 9
    assert math.isclose(float(terms["psnr"]), -10 * math.log10(mse["fine"]), rel_tol=1e-5)


def test_ignored_rays_get_no_semantic_gradient() -> None:
    out = _out(6, 3)
    target = torch.tensor([0, IGNORE, 2, IGNORE, 1, 1])
    total, _ = render_loss(out, target, torch.rand(6, 3), LossConfig(lambda_rgb=0.0))
    total.backward()
    grad = out["fine"]["logits"].grad
    assert grad is not None
    torch.testing.assert_close(grad[[1, 3]], torch.zeros(2, 3), atol=0.0, rtol=0.0)
    assert float(grad[[0, 2, 4, 5]].abs().sum()) > 0


def test_batch_without_labels_is_finite_with_zero_semantic_gradient() -> None:
    out = _out(8, 4)
    target = torch.full((8,), IGNORE)
    rgb = torch.rand(8, 3)
    total, terms = render_loss(out, target, rgb, LossConfig())
    assert bool(torch.isfinite(total))
    assert float(terms["sem_coarse"]) == 0.0 and float(terms["sem_fine"]) == 0.0
    assert int(terms["n_labelled"]) == 0
    total.backward()
    for p in ("coarse", "fine"):
        torch.testing.assert_close(out[p]["logits"].grad, torch.zeros(8, 4), atol=0.0, rtol=0.0)
        assert float(out[p]["rgb"].grad.abs().sum()) > 0  # the photometric term still trains


def test_semantic_only_loss_without_labels_still_backpropagates() -> None:
    out = _out(4, 4)
    total, _ = render_loss(out, torch.full((4,), IGNORE), torch.rand(4, 3),
                           LossConfig(lambda_rgb=0.0))
    assert float(total.detach()) == 0.0
    total.backward()  # must not raise: the zero stays attached to the graph
    torch.testing.assert_close(out["fine"]["logits"].grad, torch.zeros(4, 4), atol=0.0, rtol=0.0)


def test_loss_is_float32_for_bf16_logits() -> None:
    out = _out(16, 7, grad=False)
    reference, _ = render_loss(out, torch.arange(16) % 7, torch.rand(16, 3,
                               generator=torch.Generator().manual_seed(1)), LossConfig())
    half = {p: {k: v.bfloat16() for k, v in d.items()} for p, d in out.items()}
    with torch.autocast("cpu", dtype=torch.bfloat16):
        total, _ = render_loss(half, torch.arange(16) % 7, torch.rand(16, 3,
                               generator=torch.Generator().manual_seed(1)), LossConfig())
    assert total.dtype == torch.float32
    torch.testing.assert_close(total, reference, atol=5e-2, rtol=2e-2)


def test_constant_colour_error_gives_20_db() -> None:
    out = _out(10, 2, grad=False)
    target_rgb = out["fine"]["rgb"] - 0.1  # every channel of every ray off by 0.1
    _, terms = render_loss(out, torch.zeros(10, dtype=torch.int64), target_rgb, LossConfig())
    torch.testing.assert_close(terms["psnr"], torch.tensor(20.0), atol=1e-4, rtol=0.0)


def test_labels_outside_the_label_space_raise_in_debug_mode(monkeypatch: pytest.MonkeyPatch) -> None:
    """The value check syncs the device, so it runs with SRAY_DEBUG_CHECKS=1 (the loader checks labels)."""
    import sray.model.debug_checks as debug_checks

    monkeypatch.setattr(debug_checks, "ENABLED", True)
    with pytest.raises(ValueError, match=r"label ids must lie in \[0, 3\)"):
        render_loss(_out(3, 3), torch.tensor([0, 7, IGNORE]), torch.rand(3, 3), LossConfig())
    with pytest.raises(ValueError, match="int64"):
        render_loss(_out(3, 3), torch.tensor([0, 1, 2], dtype=torch.int32), torch.rand(3, 3),
                    LossConfig())
