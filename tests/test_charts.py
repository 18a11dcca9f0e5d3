"""Fleet charts: step-function averaging against hand-computed values, PNGs of synthetic fleets."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sray.platform.finetune.methods.registry import METHODS, get_method
from sray.platform.viz.charts import curve_figure, size_figure, write_fleet_charts
from sray.platform.viz.curves import average_curves, curve_xy, step_hold, zero_shot_value

CHART_FILES = ["miou_vs_wall_s.png", "miou_vs_step.png", "psnr_vs_wall_s.png", "psnr_vs_step.png",
               "miou_vs_artifact_bytes.png"]


def synthetic_result(scene: str, method: str, n_points: int = 5, status: str = "finished",
                     final: float = 0.6) -> dict:
    """A fleet result (docs/CONTRACTS.md) whose curve rises from a start value to ``final``."""
    start = 0.4 if method == "sray" else 0.02
    dt = 3.0 if method == "sray" else 1.0
    curve = [{"step": 20 * i, "wall_s": dt * i,
              "miou": start + (final - start) * (1 - math.exp(-i / 2)),
              "miou_per_image": start + (final - start) * (1 - math.exp(-i / 2)) * 0.9,
              "psnr": 14.0 + 6 * (1 - math.exp(-i / 2))} for i in range(n_points)] if status == "finished" else []
    return {"scene": scene, "method": method, "status": status,
            "error": None if status == "finished" else "RuntimeError: injected failure", "attempts": 2,
            "steps_used": curve[-1]["step"] if curve else 0, "max_steps": 400, "stopped_early": n_points < 6,
            "wall_s": curve[-1]["wall_s"] if curve else 0.0, "miou_before": curve[0]["miou"] if curve else None,
            "miou_after": max(p["miou"] for p in curve) if curve else None,
            "psnr_after": curve[-1]["psnr"] if curve else None,
            "artifact_bytes": 40_000 if method == "sray" else 2_500_000, "full_checkpoint_bytes": 2_000_000,
            "child_run_id": None, "curve": curve,
            "protocol": None if status != "finished" else {
                "source_rule": "frustum-overlap v1" if method == "sray" else "none (per-scene model)",
                "n_source": 8 if method == "sray" else 0, "stride": 2, "render": "full", "inputs": "rgb",
                "miou": "dataset-level, classes present in ground truth", "miou_per_image": "per-image mean"}}


def mixed_fleet() -> list[dict]:
    """Three scenes: both methods; S-Ray only (its Semantic-NeRF failed); a single-point S-Ray curve.
    A fourth scene failed for every method."""
    return [synthetic_result("scene_a", "sray", 6), synthetic_result("scene_a", "semantic-nerf", 10),
            synthetic_result("scene_b", "sray", 8), synthetic_result("scene_b", "semantic-nerf", status="failed"),
            synthetic_result("scene_c", "sray", 1), synthetic_result("scene_c", "semantic-nerf", 7),
            synthetic_result("scene_d", "sray", status="failed")]


def test_average_of_hand_made_curves():
    a = (np.array([0.0, 10.0, 20.0]), np.array([0.2, 0.4, 0.5]))
    b = (np.array([0.0, 15.0]), np.array([0.1, 0.3]))
    grid, mean = average_curves([a, b])
    # on 0, 10, 15, 20: a holds 0.2, 0.4, 0.4, 0.5 and b holds 0.1, 0.1, 0.3, 0.3
    np.testing.assert_allclose(grid, [0.0, 10.0, 15.0, 20.0])
    np.testing.assert_allclose(mean, [0.15, 0.25, 0.35, 0.40], atol=1e-12)
    # a curve that starts late: the mean starts where every curve has a value (at 5, a holds 0.2)
    grid, mean = average_curves([a, (np.array([5.0]), np.array([1.0]))])
    np.testing.assert_allclose(grid, [5.0, 10.0, 20.0])
    np.testing.assert_allclose(mean, [0.6, 0.7, 0.75], atol=1e-12)
    # a single-point curve averages with itself; no curve gives nothing
    grid, mean = average_curves([(np.array([0.0]), np.array([0.3]))])
    np.testing.assert_allclose(grid, [0.0])
    np.testing.assert_allclose(mean, [0.3])
    grid, mean = average_curves([])
    assert grid.size == 0 and mean.size == 0


@settings(max_examples=80, deadline=None)
@given(xs=st.lists(st.integers(0, 50), min_size=1, max_size=8),
       grid=st.lists(st.integers(-5, 60), min_size=1, max_size=10))
def test_step_hold_matches_a_naive_loop(xs, grid):
    x = np.sort(np.asarray(xs, float))
    y = np.arange(len(x), dtype=float) * 1.5 + 0.25
    got = step_hold(x, y, np.asarray(grid, float))
    for g, value in zip(grid, got):
        before = [yi for xi, yi in zip(x, y) if xi <= g]
        if before:
            assert value == before[-1]
        else:
            assert math.isnan(value)


def test_curve_points_are_sorted_and_missing_values_dropped():
    curve = [{"step": 20, "wall_s": 2.0, "miou": 0.5, "psnr": None}, {"step": 0, "wall_s": 0.0, "miou": 0.4,
                                                                      "psnr": 12.0},
             {"step": 40, "wall_s": 4.0, "miou": float("nan"), "psnr": 13.0}]
    x, y = curve_xy(curve, "step", "miou")
    np.testing.assert_allclose(x, [0, 20])
    np.testing.assert_allclose(y, [0.4, 0.5])
    x, y = curve_xy(curve, "wall_s", "psnr")
    np.testing.assert_allclose(x, [0.0, 4.0])
    np.testing.assert_allclose(y, [12.0, 13.0])
    assert zero_shot_value({"method": "sray", "curve": curve}, "miou", METHODS) is None  # first point is not step 0
    assert zero_shot_value({"method": "sray", "curve": curve[1:2]}, "miou", METHODS) == 0.4
    assert zero_shot_value({"method": "semantic-nerf", "curve": curve[1:2]}, "miou", METHODS) is None


def _colour_pixels(png, hex_colour: str, tol: int = 12) -> int:
    image = cv2.cvtColor(cv2.imread(str(png)), cv2.COLOR_BGR2RGB).astype(int)
    rgb = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)])
    return int((np.abs(image - rgb).max(axis=-1) <= tol).sum())


def test_mixed_fleet_charts_are_written_and_skip_failures(tmp_path):
    results = mixed_fleet()
    paths = write_fleet_charts(results, tmp_path / "charts", METHODS)
    assert [p.name for p in paths] == CHART_FILES
    for p in paths:
        image = cv2.imread(str(p))
        assert image is not None, f"{p} is not a readable PNG"
        h, w = image.shape[:2]
        assert 450 <= w <= 2600 and 400 <= h <= 2200, f"{p.name}: {w}x{h} px"
        assert image.std() > 10, f"{p.name} looks blank"
        assert _colour_pixels(p, get_method("sray").style.color) > 50
        assert _colour_pixels(p, get_method("semantic-nerf").style.color) > 20
    assert not list((tmp_path / "charts").glob(".*"))  # no temporary files left
    # panels: the mean, then scenes a, b, c; scene_d (all failed) has none; the footnote names failures
    fig = curve_figure(results, "miou", "wall_s", METHODS)
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible()]
    assert titles == ["mean over scenes (S-Ray finetune: 3, Semantic-NeRF from scratch: 2)",
                      "scene scene_a", "scene scene_b", "scene scene_c"]
    texts = " ".join(t.get_text() for sub in fig.subfigs for t in sub.texts)
    assert "scene_b/semantic-nerf (RuntimeError: injected failure)" in texts and "scene_d/sray" in texts
    assert "vs wall-clock time" in texts and "dataset-level" in texts
    # the footnote carries the protocol of each method's numbers
    assert "Protocol (sray): sources: 8 per query" in texts and "Protocol (semantic-nerf): sources: none" in texts
    assert "(stride 2), so no SSIM" in " ".join(texts.split())


def test_single_method_fleet_and_degenerate_inputs(tmp_path):
    results = [synthetic_result("only_scene", "sray", 4)]
    paths = write_fleet_charts(results, tmp_path, METHODS)
    assert [p.name for p in paths] == CHART_FILES
    for p in paths:
        assert cv2.imread(str(p)) is not None
        assert _colour_pixels(p, get_method("semantic-nerf").style.color, tol=6) == 0  # no Semantic-NeRF anywhere
    assert [ax.get_title() for ax in curve_figure(results, "psnr", "step", METHODS).axes if ax.get_visible()] == \
        ["scene only_scene"]
    # every result failed: nothing to draw, nothing written
    assert write_fleet_charts([synthetic_result("x", "sray", status="failed")], tmp_path / "none", METHODS) == []
    assert not (tmp_path / "none").exists()
    with pytest.raises(ValueError, match=r"fleet result x/sray: fields \['curve'\] are missing"):
        write_fleet_charts([{k: v for k, v in synthetic_result("x", "sray").items() if k != "curve"}], tmp_path,
                           METHODS)
    with pytest.raises(ValueError, match="field 'method' is 'nerf'"):
        write_fleet_charts([synthetic_result("x", "sray") | {"method": "nerf"}], tmp_path, METHODS)


def test_legends_name_the_inputs_each_method_was_given():
    """An RGB-D method (2d-transfer) beside RGB ones: every legend entry, zero-shot lines included, ends with the
    inputs its results' protocol records; a result without a protocol adds no tag."""
    transfer = synthetic_result("scene_a", "2d-transfer", 4)
    transfer["protocol"] = transfer["protocol"] | {"source_rule": "frustum-overlap v1", "n_source": 8, "inputs": "rgbd"}
    results = [synthetic_result("scene_a", "sray", 4), synthetic_result("scene_a", "semantic-nerf", 4), transfer]
    for fig in (curve_figure(results, "miou", "step", METHODS), size_figure(results, METHODS)):
        legend = [t.get_text() for sub in fig.subfigs for lg in sub.legends for t in lg.get_texts()]
        assert legend == ["S-Ray zero-shot (step 0, no per-scene steps) [RGB]",
                          "2d-transfer zero-shot (pretrained segmenter) [RGB-D]", "S-Ray finetune [RGB]",
                          "Semantic-NeRF from scratch [RGB]", "2d-transfer finetune [RGB-D]",
                          "finetune stopped early (held-out score stopped improving)"]
    texts = " ".join(t.get_text() for sub in curve_figure(results, "miou", "step", METHODS).subfigs for t in sub.texts)
    assert "Protocol (2d-transfer): " in texts and "inputs: rgbd" in texts
    bare = synthetic_result("scene_a", "sray", 4) | {"protocol": None}
    legend = [t.get_text() for sub in curve_figure([bare], "miou", "step", METHODS).subfigs for lg in sub.legends
              for t in lg.get_texts()]
    assert legend[:2] == ["S-Ray zero-shot (step 0, no per-scene steps)", "S-Ray finetune"]
