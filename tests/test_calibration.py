"""Temperature calibration of the fast render's coarse confidence: the fit recovers a known temperature, and the
fast rule's fine-pass share follows the temperature."""

from __future__ import annotations

import pytest
import torch

from sray.model.calibration import fit_temperature, nll
from sray.model.fast_render import FastRender, needs_fine, render_rays_fast


@pytest.mark.parametrize("true_t", [0.5, 1.0, 2.5])
def test_calibration_recovers_a_known_temperature(true_t: float) -> None:
    """Labels drawn from softmax(z / T): the fitted temperature of z is T, and it beats T = 1 on NLL."""
    g = torch.Generator().manual_seed(0)
    z = 3.0 * torch.randn(6000, 6, generator=g)
    labels = torch.multinomial(torch.softmax(z / true_t, dim=-1), 1, generator=g).squeeze(-1)
    labels[:200] = 255  # ignored
    fitted = fit_temperature(z, labels)
    assert fitted == pytest.approx(true_t, rel=0.08)
    keep = labels != 255
    assert nll(z[keep], labels[keep], fitted) <= nll(z[keep], labels[keep], 1.0) + 1e-6


def test_calibration_refuses_unusable_input() -> None:
    with pytest.raises(ValueError, match="no labelled"):
        fit_temperature(torch.zeros(3, 4), torch.full((3,), 255))
    with pytest.raises(ValueError, match="finite"):
        fit_temperature(torch.tensor([[float("-inf"), 0.0]]), torch.tensor([1]))
    with pytest.raises(ValueError, match="temperature"):
        FastRender(temperature=0.0)


def test_the_fine_pass_share_grows_with_the_temperature() -> None:
    """A higher temperature flattens the coarse softmax, so more rays fall below the confidence; the renderer's
    fine pass runs exactly on the rays ``needs_fine`` names."""
    g = torch.Generator().manual_seed(1)
    logits = 4.0 * torch.randn(400, 5, generator=g)
    shares = [float(needs_fine(logits, 0.9, t).float().mean()) for t in (0.25, 0.5, 1.0, 2.0, 4.0, 50.0)]
    assert shares == sorted(shares) and shares[0] < 0.2 and shares[-1] == 1.0

    calls: list[int] = []

    def field(name, o, d, z, lo, hi):
        if name == "fine":
            calls.append(o.shape[0])
        n = z.shape[1]
        return {"sigma": torch.ones(o.shape[0], n), "rgb": torch.zeros(o.shape[0], n, 3),
                "logits": logits[: o.shape[0], None, :].expand(-1, n, -1) if name == "coarse" else
                torch.zeros(o.shape[0], n, 5)}

    origins, dirs = torch.zeros(400, 3), torch.tensor([[0.0, 0.0, 1.0]]).expand(400, 3)
    for t in (0.5, 2.0):
        calls.clear()
        out = render_rays_fast(field, origins, dirs, 1.0, 4.0, 8, 8, 0.9, temperature=t)
        assert out["coarse"]["logits"].shape == (400, 5)
        assert calls == [int(needs_fine(out["coarse"]["logits"], 0.9, t).sum())]
