"""Semantic render PNGs logged to MLflow: the fixed palette, colorize, and the panel read back."""

from __future__ import annotations

import itertools

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from sray.data_tools.label_spaces import NYU40, SCANNET20
from sray.data_tools.scene import IGNORE_ID
from sray.platform.viz.palette import IGNORE_COLOR, SCANNET20_COLORS, colorize, palette
from sray.platform.viz.renders import CORRECT_COLOR, ERROR_COLOR, error_map, panel_grid, render_panel


def _lab(colors: np.ndarray) -> np.ndarray:
    """CIELAB (L in 0..100) of uint8 RGB colours (N, 3), through OpenCV."""
    lab = cv2.cvtColor(colors.reshape(1, -1, 3), cv2.COLOR_RGB2LAB).reshape(-1, 3).astype(float)
    lab[:, 0] *= 100.0 / 255.0
    lab[:, 1:] -= 128.0
    return lab


def test_scannet_palette_is_twenty_distinct_colours_away_from_black_white_grey():
    colors = palette(20)
    assert colors.shape == (20, 3) and colors.dtype == np.uint8 and len(SCANNET20_COLORS) == len(SCANNET20)
    lab = _lab(colors)
    closest = min(np.linalg.norm(a - b) for a, b in itertools.combinations(lab, 2))
    assert closest >= 30.0
    reserved = _lab(np.array([IGNORE_COLOR, (255, 255, 255), CORRECT_COLOR, (128, 128, 128)], np.uint8))
    assert min(np.linalg.norm(c - r) for c in lab for r in reserved) >= 20.0


def test_larger_label_spaces_extend_the_palette_without_changing_it():
    big = palette(len(NYU40))
    assert len({tuple(c) for c in big}) == len(NYU40)
    np.testing.assert_array_equal(big[:20], palette(20))
    with pytest.raises(ValueError):
        palette(0)


@settings(max_examples=60, deadline=None)
@given(labels=hnp.arrays(np.int64, hnp.array_shapes(min_dims=2, max_dims=2, max_side=12),
                         elements=st.one_of(st.integers(0, 19), st.just(IGNORE_ID))))
def test_colorize_matches_a_pixel_loop(labels):
    out = colorize(labels, 20, IGNORE_ID)
    table = palette(20)
    expected = np.zeros((*labels.shape, 3), np.uint8)
    for (i, j), v in np.ndenumerate(labels):
        expected[i, j] = IGNORE_COLOR if v == IGNORE_ID else table[v]
    np.testing.assert_array_equal(out, expected)


def test_colorize_names_bad_ids():
    with pytest.raises(ValueError, match=r"\[20, 77\] are outside 0..19"):
        colorize(np.array([[0, 20], [77, IGNORE_ID]]), 20)
    with pytest.raises(ValueError, match="integer"):
        colorize(np.zeros((2, 2), np.float32), 20)


def _scene_labels() -> tuple[np.ndarray, np.ndarray]:
    """A 30 x 40 ground truth with walls, floor, a table and an unlabelled strip; a prediction
    that is right except for a chair where the table is, and guesses on the unlabelled strip."""
    gt = np.zeros((30, 40), np.int64)
    gt[15:] = 1
    gt[18:26, 10:22] = 6
    gt[:, :5] = IGNORE_ID
    pred = gt.copy()
    pred[:, :5] = 3
    pred[20:24, 12:18] = 4
    return pred, gt


def test_panel_png_reads_back_with_the_right_colours(tmp_path):
    pred, gt = _scene_labels()
    rng = np.random.default_rng(0)
    gt_rgb = rng.random((30, 40, 3)).astype(np.float32)
    pred_rgb = (rng.random((30, 40, 3)) * 255).astype(np.uint8)
    path = render_panel(pred, gt, pred_rgb, gt_rgb, SCANNET20, tmp_path / "renders" / "view.png", title="step 7")
    image = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    assert sorted(p.name for p in path.parent.iterdir()) == ["view.png"]  # no temp file left

    legend_ids = [0, 1, 3, 4, 6]
    grid = panel_grid((30, 40), len(legend_ids) + 1)  # + the unlabelled entry
    assert image.shape[:2] == grid.size
    s = grid.scale

    def tile(name: str) -> np.ndarray:
        """The tile's pixels, sampled back to the view's resolution (one pixel per enlarged block)."""
        x, y, w, h = grid.tiles[name]
        return image[y + s // 2:y + h:s, x + s // 2:x + w:s]

    np.testing.assert_array_equal(tile("pred_sem"), colorize(pred, 20))
    np.testing.assert_array_equal(tile("gt_sem"), colorize(gt, 20))
    assert tuple(tile("gt_sem")[5, 2]) == IGNORE_COLOR and tuple(tile("gt_sem")[20, 15]) == SCANNET20_COLORS[6]
    np.testing.assert_array_equal(tile("pred_rgb"), pred_rgb)
    np.testing.assert_array_equal(tile("gt_rgb"), (gt_rgb * 255 + 0.5).astype(np.uint8))
    errors = tile("error")
    assert tuple(errors[21, 13]) == ERROR_COLOR and tuple(errors[5, 20]) == CORRECT_COLOR
    assert tuple(errors[5, 2]) == (0, 0, 0)  # unlabelled: never an error, whatever was predicted
    assert (errors == ERROR_COLOR).all(axis=-1).sum() == 4 * 6

    swatch_colors = [tuple(image[y + 5, x + 5]) for x, y in grid.swatches]
    assert swatch_colors == [SCANNET20_COLORS[c] for c in legend_ids] + [IGNORE_COLOR]


def test_error_map_matches_its_definition():
    pred, gt = _scene_labels()
    out = error_map(pred, gt, IGNORE_ID)
    wrong = (gt != IGNORE_ID) & (pred != gt)
    np.testing.assert_array_equal((out == ERROR_COLOR).all(-1), wrong)
    np.testing.assert_array_equal((out == 0).all(-1), gt == IGNORE_ID)


def test_panel_rejects_mismatched_inputs(tmp_path):
    pred, gt = _scene_labels()
    rgb = np.zeros((30, 40, 3), np.float32)
    with pytest.raises(ValueError, match="same"):
        render_panel(pred[:10], gt, rgb, rgb, SCANNET20, tmp_path / "a.png")
    with pytest.raises(ValueError, match="pred_rgb"):
        render_panel(pred, gt, rgb[:, :5], rgb, SCANNET20, tmp_path / "a.png")
