"""Volume rendering against analytic integrals: sampling, hierarchical resampling, compositing."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from sray.model.rendering import (
    bin_edges,
    composite,
    merge_samples,
    sample_pdf,
    sample_uniform,
)

TOL = {"atol": 1e-5, "rtol": 1e-5}


def _bounds(n_rays: int, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Random per-ray near in [0.1, 1) and far = near + [0.5, 4)."""
    g = torch.Generator().manual_seed(seed)
    near = 0.1 + 0.9 * torch.rand(n_rays, generator=g)
    return near, near + 0.5 + 3.5 * torch.rand(n_rays, generator=g)


@pytest.mark.parametrize("stratified", [False, True])
@pytest.mark.parametrize("sigma", [0.05, 0.7, 3.0, 20.0])
def test_constant_density_gives_analytic_opacity(stratified: bool, sigma: float) -> None:
    near, far = _bounds(64)
    z = sample_uniform(near, far, 48, stratified, torch.Generator().manual_seed(1))
    colour = torch.tensor([0.2, 0.5, 0.9])
    out = composite(
        torch.full_like(z, sigma), z, near, far, {"rgb": colour.expand(64, 48, 3).clone()}
    )
    expected = 1 - torch.exp(-sigma * (far - near))
    torch.testing.assert_close(out["opacity"], expected, **TOL)
    # A constant colour renders as opacity times that colour.
    torch.testing.assert_close(out["rgb"], expected[:, None] * colour, **TOL)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20),
    st.floats(0.01, 10.0),
    st.floats(0.0, 2.0),
    st.floats(0.1, 5.0),
)
def test_weights_match_exact_integral_of_constant_density_for_any_sampling(
    fracs: list[float], sigma: float, near_v: float, span: float
) -> None:
    near, far = torch.tensor([near_v], dtype=torch.float64), torch.tensor([near_v + span])
    far = far.double()
    z = (near + span * torch.tensor(sorted(fracs), dtype=torch.float64))[None]  # (1, N)
    out = composite(torch.full_like(z, sigma), z, near, far, {})
    # Each sample's weight is the light absorbed inside the interval it stands for.
    e = bin_edges(z, near, far)[0] - near_v
    expected = torch.exp(-sigma * e[:-1]) - torch.exp(-sigma * e[1:])
    torch.testing.assert_close(out["weights"][0].double(), expected, atol=2e-6, rtol=1e-5)
    assert math.isclose(float(out["opacity"][0]), 1 - math.exp(-sigma * span), abs_tol=2e-6)


def test_single_class_semantics_renders_that_class_for_any_density() -> None:
    g = torch.Generator().manual_seed(3)
    near, far = _bounds(200)
    z = sample_uniform(near, far, 32, True, g)
    sigma = torch.rand(200, 32, generator=g) * torch.logspace(-2, 2, 200)[:, None]
    logits = torch.randn(200, 32, 6, generator=g)
    logits[..., 4] = logits.max(-1).values + 0.5  # class 4 wins at every sample
    out = composite(sigma, z, near, far, {"logits": logits})
    assert bool((out["opacity"] > 0).all())
    assert bool((out["logits"].argmax(-1) == 4).all())


def test_composite_is_finite_for_empty_and_opaque_space() -> None:
    near, far = _bounds(8)
    z = sample_uniform(near, far, 16, False)
    values = {"rgb": torch.rand(8, 16, 3)}
    empty = composite(torch.zeros_like(z), z, near, far, values)
    for v in empty.values():
        assert bool(torch.isfinite(v).all())
    torch.testing.assert_close(empty["opacity"], torch.zeros(8), atol=0.0, rtol=0.0)
    solid = composite(torch.full_like(z, 1e6), z, near, far, values)
    for v in solid.values():
        assert bool(torch.isfinite(v).all())
    torch.testing.assert_close(solid["opacity"], torch.ones(8), **TOL)
    # All light is absorbed in the first interval: colour and depth are the first sample's.
    torch.testing.assert_close(solid["rgb"], values["rgb"][:, 0], **TOL)
    torch.testing.assert_close(solid["depth"], z[:, 0], **TOL)


def test_a_huge_density_does_not_erase_the_transmittance_before_it() -> None:
    near, far = torch.tensor([0.0]), torch.tensor([4.0])
    z = torch.tensor([[0.5, 1.5, 2.5, 3.5]])
    sigma = torch.tensor([[0.1, 0.1, 1e8, 0.1]])
    w = composite(sigma, z, near, far, {})["weights"][0]
    # T before the wall is exp(-0.1 * 2): the wall absorbs exactly that.
    torch.testing.assert_close(w[2], torch.tensor(math.exp(-0.2)), **TOL)


def test_composite_runs_in_float32_under_bf16_autocast() -> None:
    near, far = _bounds(32)
    z = sample_uniform(near, far, 24, False)
    g = torch.Generator().manual_seed(5)
    sigma = torch.rand(32, 24, generator=g) * 2
    feats = torch.randn(32, 24, 8, generator=g)
    head = torch.randn(8, 5, generator=g)
    reference = composite(sigma, z, near, far, {"logits": feats @ head})
    with torch.autocast("cpu", dtype=torch.bfloat16):
        logits = feats @ head  # bf16 under autocast
        assert logits.dtype == torch.bfloat16
        out = composite(sigma.bfloat16(), z, near, far, {"logits": logits})
    for key in ("weights", "opacity", "depth", "logits"):
        assert out[key].dtype == torch.float32
        assert bool(torch.isfinite(out[key]).all())
    # Only the bf16 rounding of the inputs (8 bits of mantissa) separates the two.
    torch.testing.assert_close(out["opacity"], reference["opacity"], atol=2e-2, rtol=2e-2)
    torch.testing.assert_close(out["logits"], reference["logits"], atol=0.15, rtol=5e-2)


def test_sample_uniform_bins() -> None:
    near, far = _bounds(16)
    centres = sample_uniform(near, far, 10, False)
    width = (far - near)[:, None] / 10
    torch.testing.assert_close(centres, near[:, None] + width * (torch.arange(10) + 0.5), **TOL)
    jittered = sample_uniform(near, far, 10, True, torch.Generator().manual_seed(0))
    assert bool((jittered - near[:, None] >= width * torch.arange(10) - 1e-6).all())
    assert bool((jittered - near[:, None] <= width * (torch.arange(10) + 1) + 1e-6).all())
    again = sample_uniform(near, far, 10, True, torch.Generator().manual_seed(0))
    torch.testing.assert_close(jittered, again, atol=0.0, rtol=0.0)


@pytest.mark.parametrize("deterministic", [True, False])
def test_sample_pdf_concentrates_on_a_weight_spike(deterministic: bool) -> None:
    near, far = _bounds(50)
    z = sample_uniform(near, far, 32, True, torch.Generator().manual_seed(2))
    weights = torch.zeros_like(z)
    weights[:, 13] = 0.95
    fine = sample_pdf(z, weights, near, far, 64, deterministic, torch.Generator().manual_seed(4))
    edges = bin_edges(z, near, far)
    inside = (fine >= edges[:, 13:14]) & (fine <= edges[:, 14:15])
    assert float(inside.float().mean(-1).min()) >= 0.9
    assert bool((fine[:, 1:] >= fine[:, :-1]).all())
    assert bool((fine >= near[:, None]).all()) and bool((fine <= far[:, None]).all())


def test_sample_pdf_falls_back_to_uniform_for_zero_weights() -> None:
    near, far = _bounds(10)
    z = sample_uniform(near, far, 7, True, torch.Generator().manual_seed(6))
    fine = sample_pdf(z, torch.zeros_like(z), near, far, 20, deterministic=True)
    torch.testing.assert_close(fine, sample_uniform(near, far, 20, False), atol=1e-5, rtol=1e-5)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=2, max_size=12), st.integers(0, 10_000))
def test_sample_pdf_follows_the_weight_distribution(weights_list: list[float], seed: int) -> None:
    n_bins = len(weights_list)
    weights = torch.tensor([weights_list])
    near, far = torch.tensor([1.0]), torch.tensor([3.0])
    z = sample_uniform(near, far, n_bins, True, torch.Generator().manual_seed(seed))
    n = 400
    fine = sample_pdf(z, weights, near, far, n, deterministic=True)
    edges = bin_edges(z, near, far)[0]
    counts = torch.histogram(fine[0].double(), bins=edges.double()).hist
    widths = edges[1:] - edges[:-1]
    mass = weights[0] + 1e-5 * widths / 2.0
    # Deterministic quantiles put n * p_k samples (+-1 for rounding) in bin k.
    expected = n * mass / mass.sum()
    assert bool(((counts - expected.double()).abs() <= 1.0 + 1e-3).all())
    assert bool((fine[:, 1:] >= fine[:, :-1]).all())


def test_sample_pdf_detaches_weights() -> None:
    near, far = _bounds(4)
    z = sample_uniform(near, far, 8, False)
    weights = torch.rand(4, 8, requires_grad=True)
    assert not sample_pdf(z, weights, near, far, 8, True).requires_grad


def test_merge_samples_is_the_sorted_union() -> None:
    a, b = torch.rand(5, 6), torch.rand(5, 3)
    merged = merge_samples(a, b)
    assert merged.shape == (5, 9)
    assert bool((merged[:, 1:] >= merged[:, :-1]).all())
    torch.testing.assert_close(merged, torch.cat([a, b], -1).sort(-1).values, atol=0.0, rtol=0.0)


def test_bad_inputs_raise_clear_errors() -> None:
    z = torch.rand(3, 4).sort(-1).values
    with pytest.raises(ValueError, match="`near` must be a tensor of shape"):
        composite(torch.ones(3, 4), z, torch.zeros(()), torch.ones(3), {})
    with pytest.raises(ValueError, match="reserved"):
        composite(torch.ones(3, 4), z, torch.zeros(3), torch.ones(3),
                  {"depth": torch.ones(3, 4, 1)})
    sample_uniform(torch.ones(3), torch.zeros(3), 4, False)  # a value check: off by default (no device sync)


def test_bound_values_are_checked_in_debug_mode(monkeypatch: pytest.MonkeyPatch) -> None:
    """With SRAY_DEBUG_CHECKS=1 the value check (which syncs the device) names the problem."""
    import sray.model.debug_checks as debug_checks

    monkeypatch.setattr(debug_checks, "ENABLED", True)
    with pytest.raises(ValueError, match="far < near"):
        sample_uniform(torch.ones(3), torch.zeros(3), 4, False)


@pytest.mark.gpu
def test_cuda_fp16_autocast_matches_cpu_float32() -> None:
    near, far = _bounds(64)
    g = torch.Generator().manual_seed(7)
    z = sample_uniform(near, far, 32, True, g)
    sigma = torch.rand(64, 32, generator=g) * 5
    logits = torch.randn(64, 32, 6, generator=g)
    reference = composite(sigma, z, near, far, {"logits": logits})
    cuda = [t.cuda() for t in (sigma, z, near, far, logits)]
    with torch.autocast("cuda", dtype=torch.float16):
        out = composite(cuda[0].half(), cuda[1], cuda[2], cuda[3], {"logits": cuda[4].half()})
    assert out["weights"].dtype == torch.float32
    torch.testing.assert_close(out["opacity"].cpu(), reference["opacity"], atol=5e-3, rtol=5e-3)
    torch.testing.assert_close(out["logits"].cpu(), reference["logits"], atol=2e-2, rtol=1e-2)


def test_opacity_of_a_slanted_ray_is_the_analytic_metric_integral() -> None:
    """Constant sigma over z in [near, far] along a ray with |d| = l: opacity = 1 - exp(-sigma (far - near) l)."""
    sigma, near_v, far_v = 0.7, 1.0, 3.0
    lengths = torch.tensor([1.0, 1.22, 1.5])  # centre ray, a ScanNet corner ray, a wide-angle corner
    z = sample_uniform(torch.full((3,), near_v), torch.full((3,), far_v), 32, stratified=False)
    out = composite(torch.full_like(z, sigma), z, torch.full((3,), near_v), torch.full((3,), far_v), {},
                    ray_length=lengths)
    expected = 1.0 - torch.exp(-sigma * (far_v - near_v) * lengths)
    torch.testing.assert_close(out["opacity"], expected, rtol=1e-5, atol=1e-6)
