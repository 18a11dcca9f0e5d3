"""Each perturbation does what its documentation says, measured back independently of its code."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sray.data_tools.perturbations import (
    exposure,
    gaussian_noise,
    jpeg,
    motion_blur,
    motion_blur_kernel,
    noisy_pose,
    occlude,
    occlusion_mask,
)


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    a, b, c, d = q / np.linalg.norm(q)  # a unit quaternion -> rotation, written out by hand
    rot = np.array([[a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)],
                    [2 * (b * c + a * d), a * a - b * b + c * c - d * d, 2 * (c * d - a * b)],
                    [2 * (b * d - a * c), 2 * (c * d + a * b), a * a - b * b - c * c + d * d]])
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rot, rng.normal(size=3) * 3
    return pose


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), rot=st.floats(0.0, 179.0), trans=st.floats(0.0, 500.0))
def test_pose_noise_has_the_requested_magnitudes(seed: int, rot: float, trans: float) -> None:
    rng = np.random.default_rng(seed)
    clean = _random_pose(rng)
    noisy = noisy_pose(clean, rot, trans, rng)
    relative = noisy[:3, :3] @ clean[:3, :3].T
    skew = (relative - relative.T) / 2  # sin(angle) * [axis]x, accurate near 0 where arccos is not
    sin = np.linalg.norm([skew[2, 1], skew[0, 2], skew[1, 0]])
    angle = np.degrees(np.arctan2(sin, (np.trace(relative) - 1) / 2))
    assert angle == pytest.approx(rot, abs=1e-6)
    assert np.linalg.norm(noisy[:3, 3] - clean[:3, 3]) * 100 == pytest.approx(trans, abs=1e-9)
    np.testing.assert_allclose(noisy[:3, :3] @ noisy[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(noisy[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_array_equal(noisy[3], [0, 0, 0, 1])


def test_pose_noise_is_seeded_and_leaves_its_input_alone() -> None:
    clean = _random_pose(np.random.default_rng(0))
    before = clean.copy()
    a = noisy_pose(clean, 2.0, 5.0, np.random.default_rng(7))
    b = noisy_pose(clean, 2.0, 5.0, np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(clean, before)


@pytest.mark.parametrize("sigma", [2.0, 10.0, 25.0])
def test_gaussian_noise_has_the_requested_sigma(sigma: float) -> None:
    grey = np.full((256, 256, 3), 128, np.uint8)
    noisy = gaussian_noise(grey, sigma, np.random.default_rng(1)).astype(np.float64)
    assert noisy.std() == pytest.approx(sigma, rel=0.03)
    assert noisy.mean() == pytest.approx(128, abs=0.3)


def test_motion_blur_keeps_the_mean_and_spreads_a_dot_along_a_line() -> None:
    rng = np.random.default_rng(2)
    flat = np.full((40, 50, 3), 77, np.uint8)
    np.testing.assert_array_equal(motion_blur(flat, 9, rng), flat)
    textured = rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    assert motion_blur(textured, 9, rng).astype(float).mean() == pytest.approx(textured.mean(), abs=0.5)
    for angle in (0.0, np.pi / 4, np.pi / 2, 2.0):
        kernel = motion_blur_kernel(9, angle)
        assert kernel.sum() == pytest.approx(1.0)
        ys, xs = np.nonzero(kernel)
        extent = np.hypot(ys.max() - ys.min(), xs.max() - xs.min())
        assert 8 - 1e-9 <= extent <= 8 * np.sqrt(2) + 1e-9  # from end to end of a 9-px line
        direction = np.array([np.sin(angle), np.cos(angle)])
        offsets = np.stack([ys - 4, xs - 4], 1)
        off_line = np.abs(offsets @ np.array([direction[1], -direction[0]]))
        assert off_line.max() <= 0.71  # every tap within half a pixel diagonal of the line


def test_exposure_scales_by_powers_of_two() -> None:
    rgb = np.arange(0, 256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, 2)
    np.testing.assert_array_equal(exposure(rgb, 1.0), np.minimum(rgb.astype(int) * 2, 255))
    np.testing.assert_array_equal(exposure(rgb, -1.0), np.rint(rgb / 2).astype(np.uint8))
    np.testing.assert_array_equal(exposure(rgb, 0.0), rgb)


def test_jpeg_error_grows_as_quality_falls() -> None:
    rng = np.random.default_rng(3)
    walk = np.cumsum(rng.normal(0, 2, (64, 96, 1)), axis=1)  # a smooth grey texture, tinted per channel
    smooth = np.clip(walk + [128, 110, 90], 0, 255).astype(np.uint8)
    errors = [np.abs(jpeg(smooth, q).astype(float) - smooth).mean() for q in (95, 50, 10)]
    assert errors[0] < errors[1] < errors[2]
    assert errors[0] < 3.0


@pytest.mark.parametrize("fraction", [0.0, 0.013, 0.1, 0.37, 0.8, 1.0])
def test_occlusion_hides_exactly_the_requested_fraction(fraction: float) -> None:
    rng = np.random.default_rng(4)
    rgb = rng.integers(0, 256, (60, 80, 3), dtype=np.uint8)
    out, mask = occlude(rgb, fraction, rng)
    assert int(mask.sum()) == round(fraction * 60 * 80)
    np.testing.assert_array_equal(out[~mask], rgb[~mask])
    assert occlusion_mask((60, 80), fraction, np.random.default_rng(9)).sum() == mask.sum()


@pytest.mark.parametrize("call", [lambda: noisy_pose(np.eye(4), -1, 0, np.random.default_rng()),
                                  lambda: motion_blur_kernel(4, 0.0), lambda: jpeg(np.zeros((4, 4, 3), np.uint8), 0),
                                  lambda: occlusion_mask((4, 4), 1.5, np.random.default_rng())])
def test_out_of_range_levels_are_refused(call) -> None:
    with pytest.raises(ValueError):
        call()
