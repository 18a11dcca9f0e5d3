"""Metric scale and depth bounds of a capture whose units are arbitrary (docs/capture.md, "Scale and depth range"):
scale = ``--scale``, else the median of metric depth / point depth over (view, point it sees) pairs; bounds from
the depth maps, else s x the views' 1st / 99th point-depth percentiles with a 10 % margin (near >= 0.05 m)."""

from __future__ import annotations

import numpy as np

MIN_PAIRS = 20
"""Fewer (view, point) pairs with a valid depth than this: the scale is not measured."""
LO_PCT, HI_PCT, MARGIN, MIN_NEAR = 1.0, 99.0, 0.1, 0.05
"""Per-view percentiles, relative margin and the smallest near bound (metres) of the point rule."""


def project_points(points: np.ndarray, K: np.ndarray, c2w: np.ndarray,
                   hw: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (P, 3) seen by a pinhole camera K (3, 3), c2w (4, 4) of size ``hw``: (z (n,), col (n,), row (n,))
    of those in front (z > 0) whose pixel (nearest centre, sray's pixel-centre rule) lies inside the image."""
    if len(points) == 0:
        return np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64)
    cam = (points - c2w[:3, 3]) @ c2w[:3, :3]                                  # (P, 3) = R^T (x - t)
    z = cam[:, 2]
    front = z > 1e-9
    uv = cam[front, :2] / z[front, None] @ K[:2, :2].T + K[:2, 2]              # (n, 2)
    col, row = np.floor(uv[:, 0] + 0.5).astype(np.int64), np.floor(uv[:, 1] + 0.5).astype(np.int64)
    inside = (col >= 0) & (col < hw[1]) & (row >= 0) & (row < hw[0])
    return z[front][inside], col[inside], row[inside]


def depth_ratios(points: np.ndarray, K: np.ndarray, c2w: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
    """Ratios (n,) metric depth / capture-unit depth of the points (P, 3) a view sees where its depth is known."""
    z, col, row = project_points(points, K, c2w, depth_m.shape)
    metric = depth_m[row, col].astype(np.float64)
    known = np.isfinite(metric) & (metric > 0)
    return metric[known] / z[known]


def measured_scale(ratios: list[np.ndarray]) -> float | None:
    """Median of every view's :func:`depth_ratios`, or None with fewer than :data:`MIN_PAIRS` of them."""
    values = np.concatenate(ratios) if ratios else np.zeros(0)
    return float(np.median(values)) if values.size >= MIN_PAIRS else None


def point_bounds(view_depths: list[np.ndarray], scale: float) -> tuple[float, float]:
    """(near, far) metres from each view's point depths in capture units; ValueError when no view sees one."""
    seen = [d for d in view_depths if d.size]
    if not seen:
        raise ValueError("no view sees any 3D point in front of it: near/far cannot be measured")
    lo = min(float(np.percentile(d, LO_PCT)) for d in seen)
    hi = max(float(np.percentile(d, HI_PCT)) for d in seen)
    return max(scale * lo * (1.0 - MARGIN), MIN_NEAR), scale * hi * (1.0 + MARGIN)


def choose_scale(given: float | None, measured: float | None, where: str) -> tuple[float, str]:
    """(metres per capture unit, how found): ``given`` first, then ``measured``, else a ValueError."""
    if given is not None:
        if not (np.isfinite(given) and given > 0):
            raise ValueError(f"--scale must be a positive number of metres per capture unit, got {given}")
        return float(given), "--scale"
    if measured is not None:
        return measured, "metric depth maps against the capture's 3D points (median ratio)"
    raise ValueError(f"{where}: the capture's units are unknown: pass --scale METRES_PER_UNIT, or give metric depth "
                     "maps (nerfstudio depth_file_path, with --depth-scale) together with 3D points (COLMAP "
                     "points3D, nerfstudio ply_file_path) so the scale can be measured")
