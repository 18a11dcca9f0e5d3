"""Stability axes perturb what they say, and the summary finds breaking points as defined."""

from __future__ import annotations

import numpy as np
import pytest

from sray.platform.stability.axes import AXES, POSE_CM_PER_DEG, PRESETS, perturb_views
from sray.platform.stability.report import axis_table, breaking_point, breaking_summary, level_stats


def _views(m: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    c2w = np.repeat(np.eye(4)[None], m, 0)
    c2w[:, :3, 3] = rng.normal(size=(m, 3))
    return rng.integers(0, 256, (m, 24, 32, 3), dtype=np.uint8), c2w


def test_pose_axis_level_sets_rotation_and_translation_of_every_view() -> None:
    rgb, c2w = _views()
    out_rgb, out = perturb_views("pose_noise", 4.0, rgb, c2w, np.random.default_rng(1))
    np.testing.assert_array_equal(out_rgb, rgb)
    for clean, noisy in zip(c2w, out):
        rel = noisy[:3, :3] @ clean[:3, :3].T
        assert np.degrees(np.arccos(np.clip((np.trace(rel) - 1) / 2, -1, 1))) == pytest.approx(4.0, abs=1e-6)
        assert np.linalg.norm(noisy[:3, 3] - clean[:3, 3]) == pytest.approx(POSE_CM_PER_DEG * 4.0 / 100)


@pytest.mark.parametrize("axis, clean", [("pose_noise", 0), ("image_noise", 0), ("blur", 0), ("exposure", 0),
                                         ("jpeg", 100), ("occlusion", 0.0)])
def test_clean_level_is_an_exact_copy_and_inputs_stay_untouched(axis: str, clean: float) -> None:
    rgb, c2w = _views()
    rgb0, c2w0 = rgb.copy(), c2w.copy()
    out_rgb, out_c2w = perturb_views(axis, clean, rgb, c2w, np.random.default_rng(2))
    np.testing.assert_array_equal(out_rgb, rgb0)
    np.testing.assert_array_equal(out_c2w, c2w0)
    perturb_views(axis, PRESETS["toy"].levels[axis][-1], rgb, c2w, np.random.default_rng(2))
    np.testing.assert_array_equal(rgb, rgb0)
    np.testing.assert_array_equal(c2w, c2w0)


def test_occlusion_axis_hides_the_fraction_in_each_view_and_is_seeded() -> None:
    rgb, c2w = _views()
    a, _ = perturb_views("occlusion", 0.25, rgb, c2w, np.random.default_rng(3))
    b, _ = perturb_views("occlusion", 0.25, rgb, c2w, np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    changed = (a != rgb).any(-1).mean(axis=(1, 2))  # a flat colour can equal a pixel by chance: at most
    assert np.all(changed <= 0.25 + 1e-9) and np.all(changed > 0.24)


def test_non_perturbing_axes_are_refused() -> None:
    rgb, c2w = _views()
    with pytest.raises(ValueError, match="source_views"):
        perturb_views("source_views", 2, rgb, c2w, np.random.default_rng())


def test_presets_cover_every_axis_with_clean_levels_first() -> None:
    for preset in PRESETS.values():
        assert set(preset.levels) == set(AXES) and preset.seeds >= 3
        assert preset.levels["precision"][0] == "fp32" and preset.levels["jpeg"][0] == 100


def _point(axis: str, method: str, level, seed: int, miou: float | None) -> dict:
    return {"axis": axis, "method": method, "level": level, "seed": seed, "x": level if miou is not None else None,
            "status": "ok" if miou is not None else "failed", "miou": miou, "psnr": None if miou is None else 20.0,
            "error": None if miou is not None else "NonFiniteOutput: x"}


def test_breaking_points_by_hand() -> None:
    points = [_point("blur", "sray", lvl, s, v + d) for lvl, v in ((1, 40.0), (3, 30.0), (7, 10.0))
              for s, d in enumerate((-1.0, 0.0, 1.0))]
    points += [_point("blur", "semantic-nerf", lvl, s, v) for lvl, v in ((1, 20.0), (3, 18.0), (7, 15.0))
               for s in range(3)]
    points += [_point("blur", "sray-no-cra", 1, s, 30.0) for s in range(3)]
    points += [_point("blur", "sray-no-cra", 3, s, None) for s in range(3)]  # every seed failed
    points += [_point("precision", "sray", "fp32", s, 40.0) for s in range(3)]
    points += [_point("precision", "sray", "bf16", s, None if s == 0 else 10.0) for s in range(3)]
    stats = level_stats(points)
    sray = [s for s in stats if s.axis == "blur" and s.method == "sray"]
    assert [s.miou_mean for s in sray] == [40.0, 30.0, 10.0] and (sray[1].miou_min, sray[1].miou_max) == (29.0, 31.0)
    assert breaking_point(sray) == (pytest.approx(3 + (30 - 20) / (30 - 10) * 4), "interpolated between levels")
    assert breaking_point([s for s in stats if s.method == "semantic-nerf"])[0] is None
    assert breaking_point([s for s in stats if s.method == "sray-no-cra"])[0] == pytest.approx(1 + 2 * 15 / 30)
    prec = [s for s in stats if s.axis == "precision"]
    assert prec[1].n_failed == 1 and prec[1].miou_mean == 10.0
    assert breaking_point(prec) == ("bf16", "first level at or below half")
    lines = breaking_summary(stats, ["blur", "precision"])
    assert "blur / sray: half the clean mIoU lost at 5 (interpolated between levels)" in lines
    assert any(line.startswith("blur / semantic-nerf: keeps half its clean mIoU at every level tested")
               for line in lines)
    table = axis_table(stats, "blur", "motion-blur length (px)")
    assert "| 3 | 30.00 (29.0-31.0) | 20.00 | 18.00 (18.0-18.0) | 20.00 | failed | failed |" in table
