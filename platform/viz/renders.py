"""One PNG per evaluated view: semantics (predicted, ground truth, errors) above, colour and legend below, the view's
pixels enlarged at exact offsets (:func:`panel_grid`); Agg canvas, no pyplot state (safe in Ray workers)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png
from sray.platform.viz.palette import IGNORE_COLOR, colorize, palette

MARGIN = 10  # pixels around and between tiles
TITLE_BAND = 22  # pixels above each tile for its caption
HEADER = 26  # pixels at the top for the panel's title
MIN_TILE_HEIGHT = 200  # small views are enlarged by an integer factor until a tile is at least this tall
LEGEND_ROW = 18  # pixels per legend entry
LEGEND_SWATCH = 14  # side of a legend colour swatch
LEGEND_COLUMN = 190  # width of one legend column
ERROR_COLOR = (255, 0, 0)  # error map: labelled pixel predicted wrong
CORRECT_COLOR = (225, 225, 225)  # error map: labelled pixel predicted right (unlabelled pixels are black)
_DPI = 100


@dataclass(frozen=True)
class PanelGrid:
    """Pixel geometry of a panel PNG (x right, y down, origin top-left): (height, width), the integer enlargement, tile
    name -> (x, y, width, height), and each legend swatch's top-left (x, y) (classes by id, then the ignore label)."""

    size: tuple[int, int]
    scale: int
    tiles: dict[str, tuple[int, int, int, int]]
    swatches: list[tuple[int, int]]


def panel_grid(hw: tuple[int, int], n_legend: int) -> PanelGrid:
    """Geometry of a panel for views of size ``hw`` with ``n_legend`` legend entries."""
    h, w = hw
    scale = max(1, math.ceil(MIN_TILE_HEIGHT / h))
    th, tw = h * scale, w * scale
    rows_per_col = max(1, th // LEGEND_ROW)
    legend_w = max(tw, LEGEND_COLUMN * max(1, math.ceil(n_legend / rows_per_col)))
    xs = [MARGIN, 2 * MARGIN + tw, 3 * MARGIN + 2 * tw]
    ys = [HEADER + TITLE_BAND, HEADER + 2 * TITLE_BAND + th + MARGIN]
    tiles = {
        "pred_sem": (xs[0], ys[0], tw, th), "gt_sem": (xs[1], ys[0], tw, th), "error": (xs[2], ys[0], tw, th),
        "pred_rgb": (xs[0], ys[1], tw, th), "gt_rgb": (xs[1], ys[1], tw, th),
        "legend": (xs[2], ys[1], legend_w, th),
    }
    swatches = [(xs[2] + (i // rows_per_col) * LEGEND_COLUMN, ys[1] + (i % rows_per_col) * LEGEND_ROW)
                for i in range(n_legend)]
    size = (ys[1] + th + MARGIN, xs[2] + max(tw, legend_w) + MARGIN)
    return PanelGrid(size=size, scale=scale, tiles=tiles, swatches=swatches)


def _as_uint8_rgb(image: np.ndarray, what: str, hw: tuple[int, int]) -> np.ndarray:
    image = np.asarray(image)
    if image.shape != (*hw, 3):
        raise ValueError(f"{what} must be (H, W, 3) = {(*hw, 3)}, got {image.shape}")
    if image.dtype == np.uint8:
        return image
    return (np.clip(np.nan_to_num(image.astype(np.float32)), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def error_map(pred: np.ndarray, gt: np.ndarray, ignore_id: int = 255) -> np.ndarray:
    """uint8 (H, W, 3): :data:`ERROR_COLOR` where pred != gt on labelled pixels, else correct/black."""
    out = np.zeros((*gt.shape, 3), np.uint8)
    labelled = gt != ignore_id
    out[labelled & (pred == gt)] = CORRECT_COLOR
    out[labelled & (pred != gt)] = ERROR_COLOR
    return out


def render_panel(pred_labels: np.ndarray, gt_labels: np.ndarray, pred_rgb: np.ndarray, gt_rgb: np.ndarray,
                 class_names: list[str], path: Path, ignore_id: int = 255, title: str = "") -> Path:
    """Write one view's panel PNG to ``path`` atomically: labels int (H, W) (gt ``ignore_id``: unlabelled), colours
    (H, W, 3) floats in [0, 1] or uint8."""
    pred, gt = np.asarray(pred_labels), np.asarray(gt_labels)
    if pred.shape != gt.shape or pred.ndim != 2:
        raise ValueError(f"pred_labels {pred.shape} and gt_labels {gt.shape} must be the same (H, W)")
    n = len(class_names)
    hw = (int(gt.shape[0]), int(gt.shape[1]))
    present = sorted(int(c) for c in np.union1d(np.unique(pred), np.unique(gt)) if c != ignore_id)
    colors = palette(n)
    legend = [(f"{c} {class_names[c]}", colors[c]) for c in present]
    if (gt == ignore_id).any():
        legend.append((f"{ignore_id} unlabelled", np.asarray(IGNORE_COLOR, np.uint8)))
    grid = panel_grid(hw, len(legend))
    images = {"pred_sem": colorize(pred, n, ignore_id), "gt_sem": colorize(gt, n, ignore_id),
              "error": error_map(pred, gt, ignore_id),
              "pred_rgb": _as_uint8_rgb(pred_rgb, "pred_rgb", hw), "gt_rgb": _as_uint8_rgb(gt_rgb, "gt_rgb", hw)}
    labelled = gt != ignore_id
    wrong = float((pred[labelled] != gt[labelled]).mean() * 100) if labelled.any() else 0.0
    captions = {"pred_sem": "predicted semantics", "gt_sem": "ground-truth semantics",
                "error": f"errors (red): {wrong:.1f}% of {int(labelled.sum())} labelled px",
                "pred_rgb": "predicted colour", "gt_rgb": "ground-truth colour", "legend": "classes present"}
    height, width = grid.size
    fig = Figure(figsize=(width / _DPI, height / _DPI), dpi=_DPI, facecolor="white")
    FigureCanvasAgg(fig)

    def text(x: int, y: int, s: str, **kw) -> None:
        fig.text(x / width, 1.0 - y / height, s, va="top", ha="left", **{"fontsize": 9, **kw})

    def place(image: np.ndarray, x: int, y: int) -> None:
        fig.figimage(image, xo=x, yo=height - y - image.shape[0], origin="upper")

    text(MARGIN, 6, title, fontsize=11, fontweight="bold")
    for name, (x, y, _, _) in grid.tiles.items():
        text(x, y - TITLE_BAND + 4, captions[name])
    for name, image in images.items():
        x, y, _, _ = grid.tiles[name]
        place(np.repeat(np.repeat(image, grid.scale, axis=0), grid.scale, axis=1), x, y)
    for (label, color), (sx, sy) in zip(legend, grid.swatches):
        place(np.broadcast_to(color, (LEGEND_SWATCH, LEGEND_SWATCH, 3)).copy(), sx, sy)
        text(sx + LEGEND_SWATCH + 6, sy, label)
    return save_png(fig, Path(path), _DPI)
