"""A fly-through frame as one picture, drawn with OpenCV (docs/render.md): title, colour | labels | depth | confidence
tiles, colour bars under depth (turbo over the scene's near..far) and confidence (viridis, 0..1), the classes present.
Every frame of a video has the same size (the legend keeps room for every class)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from sray.platform.viz.palette import colorize, palette

MARGIN = 8  # pixels around and between tiles
HEADER = 22  # pixels at the top for the frame's title
CAPTION = 18  # pixels above the tiles for their captions
BAR = 10  # height of a colour bar
BAR_BAND = BAR + 22  # pixels under the tiles for the colour bars and their labels
LEGEND_ROW = 16  # pixels per legend row
LEGEND_COLUMN = 150  # width of a legend column
SWATCH = 11  # side of a legend swatch
MIN_TILE_HEIGHT = 120  # small frames are enlarged by an integer factor until a tile is at least this tall
TILES = {"rgb": "colour", "semantics": "semantic labels", "depth": "depth (m)", "confidence": "confidence"}
"""Tile name -> caption, left to right."""
BACKGROUND = (255, 255, 255)
TEXT = (20, 20, 20)
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def _lut(colormap: int) -> np.ndarray:
    """uint8 (256, 3) RGB colours of an OpenCV colour map."""
    bgr = cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], colormap)         # (256, 1, 3)
    return np.ascontiguousarray(bgr[:, 0, ::-1])


DEPTH_COLORS = _lut(cv2.COLORMAP_TURBO)  # near (index 0) to far (255)
CONFIDENCE_COLORS = _lut(cv2.COLORMAP_VIRIDIS)  # 0 (index 0) to 1 (255)


@dataclass(frozen=True)
class PanelLayout:
    """Pixel geometry of a frame picture (x right, y down, origin top-left): (height, width), both even (encoders
    subsample colour by 2), the integer enlargement, tile name -> (x, y, width, height), legend (x, y, columns)."""

    size: tuple[int, int]
    scale: int
    tiles: dict[str, tuple[int, int, int, int]]
    legend: tuple[int, int, int]


def panel_layout(hw: tuple[int, int], n_classes: int) -> PanelLayout:
    """The layout of frames rendered at ``hw`` = (H, W) for a label space of ``n_classes`` classes."""
    h, w = hw
    scale = max(1, math.ceil(MIN_TILE_HEIGHT / h))
    th, tw = h * scale, w * scale
    y = HEADER + CAPTION
    tiles = {name: (MARGIN + i * (tw + MARGIN), y, tw, th) for i, name in enumerate(TILES)}
    width = MARGIN + len(TILES) * (tw + MARGIN)
    columns = max(1, (width - 2 * MARGIN) // LEGEND_COLUMN)
    legend_y = y + th + BAR_BAND
    height = legend_y + math.ceil(n_classes / columns) * LEGEND_ROW + MARGIN
    return PanelLayout(size=(height + height % 2, width + width % 2), scale=scale, tiles=tiles,
                       legend=(MARGIN, legend_y, columns))


def _text(image: np.ndarray, s: str, x: int, y_top: int, scale: float = 0.4) -> None:
    """Draw ``s`` with its top-left corner near (x, y_top)."""
    cv2.putText(image, s, (x, y_top + int(round(25 * scale))), _FONT, scale, TEXT, 1, cv2.LINE_AA)


def _bar(image: np.ndarray, box: tuple[int, int, int, int], colors: np.ndarray, ticks: list[str]) -> None:
    """A horizontal colour bar under tile ``box`` with ``ticks`` spread evenly under it."""
    x, y, w, h = box
    top = y + h + 4
    image[top:top + BAR, x:x + w] = colors[np.linspace(0, 255, w).round().astype(int)][None]
    for i, tick in enumerate(ticks):
        width = cv2.getTextSize(tick, _FONT, 0.35, 1)[0][0]
        along = i / max(len(ticks) - 1, 1)                                             # 0 left-aligned, 1 right
        _text(image, tick, x + int(round(along * (w - width))), top + BAR + 1, 0.35)


def _mapped(t: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """uint8 (H, W, 3) colours of values ``t`` (H, W) over [0, 1] (clipped) on a colour map (256, 3)."""
    return colors[np.round(np.clip(t, 0.0, 1.0) * 255).astype(int)]


def compose_panels(rgb: np.ndarray, label: np.ndarray, depth: np.ndarray, confidence: np.ndarray,
                   class_names: list[str], near: float, far: float, title: str, ignore_id: int = 255) -> np.ndarray:
    """uint8 (H', W', 3) picture of one frame (size :func:`panel_layout`): rgb float (H, W, 3) in [0, 1]; label int
    (H, W) class ids; depth float (H, W) metres, coloured over [``near``, ``far``]; confidence float (H, W)."""
    n = len(class_names)
    layout = panel_layout((int(label.shape[0]), int(label.shape[1])), n)
    image = np.full((*layout.size, 3), BACKGROUND, np.uint8)
    depth_t = (np.asarray(depth, np.float64) - near) / max(far - near, 1e-9)
    tiles = {"rgb": (np.clip(rgb, 0.0, 1.0) * 255 + 0.5).astype(np.uint8), "semantics": colorize(label, n, ignore_id),
             "depth": _mapped(depth_t, DEPTH_COLORS), "confidence": _mapped(confidence, CONFIDENCE_COLORS)}
    _text(image, title, MARGIN, 4, 0.45)
    for name, caption in TILES.items():
        x, y, w, h = layout.tiles[name]
        _text(image, caption, x, y - CAPTION + 2)
        image[y:y + h, x:x + w] = np.repeat(np.repeat(tiles[name], layout.scale, axis=0), layout.scale, axis=1)
    _bar(image, layout.tiles["depth"], DEPTH_COLORS, [f"{near:.2f}", f"{(near + far) / 2:.2f}", f"{far:.2f} m"])
    _bar(image, layout.tiles["confidence"], CONFIDENCE_COLORS, ["0", "0.5", "1"])
    colors = palette(n)
    x0, y0, columns = layout.legend
    rows = math.ceil(n / columns)
    for i, c in enumerate(int(c) for c in np.unique(label) if c != ignore_id):
        x, y = x0 + (i // rows) * LEGEND_COLUMN, y0 + (i % rows) * LEGEND_ROW
        image[y + 2:y + 2 + SWATCH, x:x + SWATCH] = colors[c]
        _text(image, f"{c} {class_names[c]}", x + SWATCH + 5, y + 1)
    return image
