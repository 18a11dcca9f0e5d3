"""A fixed colour per semantic class, so renders of every run and every step read the same way."""

from __future__ import annotations

import colorsys

import numpy as np

SCANNET20_COLORS: list[tuple[int, int, int]] = [
    (192, 192, 128), (128, 64, 64), (255, 0, 128), (0, 255, 0), (0, 64, 128),
    (255, 128, 0), (255, 192, 255), (0, 255, 255), (255, 64, 255), (0, 0, 255),
    (0, 128, 0), (128, 0, 128), (64, 128, 128), (128, 128, 255), (192, 192, 0),
    (0, 192, 255), (64, 64, 0), (128, 255, 128), (255, 64, 64), (0, 192, 128),
]
"""RGB of class ids 0..19 (ScanNet-20 order: wall, floor, cabinet, ...), chosen greedily from a 5-level RGB grid to
maximise the smallest CIELAB distance (>= 36), avoiding near-black, near-white and grey (ignore label, error map)."""

IGNORE_COLOR: tuple[int, int, int] = (0, 0, 0)
"""Colour of unlabelled pixels (the ignore id) in every semantic map."""

_GOLDEN = 0.618033988749895


def palette(n_classes: int) -> np.ndarray:
    """uint8 (n_classes, 3): the fixed ScanNet-20 colours, then golden-ratio hues for larger spaces."""
    if n_classes < 1:
        raise ValueError(f"n_classes must be >= 1, got {n_classes}")
    colors = list(SCANNET20_COLORS[:n_classes])
    for i in range(len(colors), n_classes):
        hue = (i * _GOLDEN) % 1.0
        sat, val = (0.85, 0.95) if i % 2 else (0.55, 0.7)
        colors.append(tuple(int(round(255 * c)) for c in colorsys.hsv_to_rgb(hue, sat, val)))
    return np.asarray(colors, dtype=np.uint8)


def colorize(labels: np.ndarray, n_classes: int, ignore_id: int = 255) -> np.ndarray:
    """uint8 (H, W, 3) image of labels (H, W), ``ignore_id`` in :data:`IGNORE_COLOR`; ValueError names unknown ids."""
    labels = np.asarray(labels)
    if labels.ndim != 2 or not np.issubdtype(labels.dtype, np.integer):
        raise ValueError(f"labels must be an integer (H, W) array, got {labels.dtype} {labels.shape}")
    ignored = labels == ignore_id
    bad = (~ignored) & ((labels < 0) | (labels >= n_classes))
    if bad.any():
        raise ValueError(f"label ids {np.unique(labels[bad])[:10].tolist()} are outside 0..{n_classes - 1} "
                         f"and not the ignore id {ignore_id}; pass the label space's class count")
    table = palette(n_classes)
    out = table[np.where(ignored, 0, labels)]
    out[ignored] = IGNORE_COLOR
    return out
