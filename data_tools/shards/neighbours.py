"""Ranked source-view neighbours, rule ``frustum-overlap`` (docs/data.md, "Source-view neighbours"): a candidate
scores the fraction of the query's depth-grid points inside its camera; a :func:`blind_views` view, whose depth is
never read, scores each candidate by the fraction of the candidate's own points inside the query camera."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.data_tools.scene import SceneMeta

RULE = "frustum-overlap"
RULE_VERSION = 2
GRID = (12, 16)
"""Rows and columns of the sparse pixel grid back-projected per view."""
MIN_POINTS = 8
"""Fewer grid pixels with known depth than this: back-project the grid at the scene's median depth."""


@dataclass
class Neighbours:
    """Ranked source-view candidates of one view: ids best first (never the view itself), overlaps in [0, 1]."""

    ids: list[str]
    scores: list[float]

    def to_json(self) -> dict:
        """JSON form stored in the shards as ``<key>.neighbours.json``."""
        return {"ids": list(self.ids), "scores": [round(float(s), 6) for s in self.scores]}

    @classmethod
    def from_json(cls, d: dict) -> Neighbours:
        """Inverse of :meth:`to_json`."""
        return cls(ids=list(d["ids"]), scores=[float(s) for s in d["scores"]])


def blind_views(meta: SceneMeta) -> set[str]:
    """Views ranked without their own depth or labels: the ``test`` split of a ``test`` scene (a user has only their
    poses and intrinsics; their depth and labels are the ground truth they are scored against)."""
    return set(meta.splits.get("test", [])) if meta.role == "test" else set()


def grid_samples(depth: np.ndarray, grid: tuple[int, int] = GRID) -> np.ndarray:
    """(u, v, z) rows (P, 3) of a sparse grid of pixel centres of one depth map (H, W), z in metres."""
    h, w = depth.shape
    rows = np.unique(np.clip(np.rint((np.arange(grid[0]) + 0.5) * h / grid[0] - 0.5), 0, h - 1).astype(int))
    cols = np.unique(np.clip(np.rint((np.arange(grid[1]) + 0.5) * w / grid[1] - 0.5), 0, w - 1).astype(int))
    v, u = np.meshgrid(rows, cols, indexing="ij")
    return np.stack([u.ravel(), v.ravel(), depth[v, u].ravel()], axis=1).astype(np.float64)


def fallback_depth(samples: list[np.ndarray], bounds: tuple[float, float] | None = None) -> float:
    """Median valid depth over grid samples (each (P, 3), of ``scene.depth_views``), used where a view lacks depth;
    in a scene without any depth, the geometric mean of its ``bounds`` (near, far) when given."""
    z = np.concatenate([s[:, 2] for s in samples]) if samples else np.zeros(0)
    z = z[np.isfinite(z) & (z > 0)]
    if z.size == 0:
        if bounds is not None and 0 < bounds[0] < bounds[1]:
            return float(np.sqrt(bounds[0] * bounds[1]))
        raise ValueError("no view has a valid depth at any grid pixel: neighbours cannot be ranked")
    return float(np.median(z))


def grid_points(samples: np.ndarray, K: np.ndarray, c2w: np.ndarray, fallback: float) -> np.ndarray:
    """World points (P, 3) of grid samples (P, 3) of one view (from :func:`grid_samples`)."""
    z = samples[:, 2]
    valid = np.isfinite(z) & (z > 0)
    if valid.sum() < MIN_POINTS:
        z, valid = np.full(z.shape, fallback), np.ones(z.shape, bool)
    pix = np.concatenate([samples[valid, :2], np.ones((int(valid.sum()), 1))], axis=1)   # (P, 3)
    cam = (pix @ np.linalg.inv(K).T) * z[valid][:, None]                                 # (P, 3)
    return cam @ c2w[:3, :3].T + c2w[:3, 3]


def projection_matrices(Ks: np.ndarray, c2ws: np.ndarray) -> np.ndarray:
    """World-to-pixel matrices (C, 3, 4) = K [R^T | -R^T t] of C cameras (Ks (C,3,3), c2ws (C,4,4))."""
    rot_t = np.transpose(c2ws[:, :3, :3], (0, 2, 1))                                   # (C, 3, 3) world->cam
    w2c = np.concatenate([rot_t, -rot_t @ c2ws[:, :3, 3:]], axis=2)                    # (C, 3, 4)
    return Ks @ w2c


def fractions_inside(points: np.ndarray, proj: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """Fraction (C,) of points (P, 3) in front of and inside each camera of ``proj`` (C, 3, 4) (K row 3: 0 0 1)."""
    if len(points) == 0:
        return np.zeros(len(proj))
    # Broadcast multiply-adds, not a matmul: with cv2 or torch imported, numpy's OpenBLAS matmul on
    # these small shapes ran 30-100x slower on the 2-core CI machine (thread-pool contention).
    rows = np.ascontiguousarray(proj.transpose(1, 2, 0))                               # (3, 4, C)
    px, py, pz = points[:, 0:1], points[:, 1:2], points[:, 2:3]                        # (P, 1) each
    x, y, z = (px * r[0] + py * r[1] + pz * r[2] + r[3] for r in rows)                 # 3 x (P, C)
    h, w = hw
    # u = x / z in [-0.5, w - 0.5) written without the division (z > 0 there)
    inside = (z > 1e-6) & (x >= -0.5 * z) & (x < (w - 0.5) * z) & (y >= -0.5 * z) & (y < (h - 0.5) * z)
    return inside.mean(axis=0)


def _seen_by_query(points: list[np.ndarray], proj_query: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """Fraction (C,) of each candidate's own world points (C arrays (P_c, 3)) seen by the query camera (3, 4)."""
    return np.array([fractions_inside(p, proj_query[None], hw)[0] for p in points])


def rank_order(capture: np.ndarray, score: np.ndarray, axes: np.ndarray, centres: np.ndarray, c2w: np.ndarray,
               k: int) -> np.ndarray:
    """Positions (<= k,) of the best of C candidates: ``score`` (C,) descending (to 1e-6), ties to the larger cosine
    between optical ``axes`` (C, 3) and ``c2w``'s, then the nearer ``centres`` (C, 3), the earlier ``capture`` (C,)."""
    cos = axes @ c2w[:3, 2]
    dist = np.linalg.norm(centres - c2w[:3, 3], axis=1)
    return np.lexsort((capture, dist, -cos, -np.round(score, 6)))[:k]                 # last key sorts first


def rank_camera(K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int], c2ws: np.ndarray, points: list[np.ndarray],
                k: int) -> tuple[np.ndarray, np.ndarray]:
    """Rank C candidates (poses c2ws (C, 4, 4) in capture order, their :func:`grid_points`) for a camera (K (3, 3),
    c2w (4, 4), ``hw``) without depth, as a :func:`blind_views` view is: (positions of the top ``k``, their scores)."""
    score = _seen_by_query(points, projection_matrices(K[None], c2w[None])[0], hw)
    order = rank_order(np.arange(len(points)), score, c2ws[:, :3, 2], c2ws[:, :3, 3], c2w, k)
    return order, score[order]


def rank_neighbours(view_ids: list[str], Ks: np.ndarray, c2ws: np.ndarray, hw: tuple[int, int],
                    points: dict[str, np.ndarray], pool: list[str], k: int) -> dict[str, Neighbours]:
    """Top-``k`` neighbours from ``pool`` for every one of V views (Ks (V, 3, 3), c2ws (V, 4, 4)). ``points``: the
    :func:`grid_points` of every view whose own depth may be used, by id; every pool view needs them, and a view
    without them (a :func:`blind_views` view) is ranked by its candidates' points."""
    index = {vid: i for i, vid in enumerate(view_ids)}
    cand = np.array([index[v] for v in pool])
    missing = [v for v in pool if v not in points]
    if missing:
        raise ValueError(f"pool views {missing} have no grid points; every candidate needs them (a view ranked "
                         "without its own depth is scored with its candidates' points)")
    proj = projection_matrices(Ks, c2ws)                                              # (V, 3, 4)
    axes, centres = c2ws[:, :3, 2], c2ws[:, :3, 3]                                    # (V, 3) each
    out: dict[str, Neighbours] = {}
    for i, vid in enumerate(view_ids):
        others = cand[cand != i]
        if vid in points:
            score = fractions_inside(points[vid], proj[others], hw)
        else:
            score = _seen_by_query([points[view_ids[j]] for j in others], proj[i], hw)
        order = rank_order(others, score, axes[others], centres[others], c2ws[i], k)
        out[vid] = Neighbours(ids=[view_ids[j] for j in others[order]], scores=[float(s) for s in score[order]])
    return out
