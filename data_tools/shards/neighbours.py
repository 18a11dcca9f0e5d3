"""Ranked source-view neighbours: which views see the most of what a view sees.

Rule ``frustum-overlap`` (version 2), computed once at shard time when depth is at hand:

1. For a view, take a sparse grid of pixels (``GRID`` = 12 rows x 16 columns, at pixel centres)
   and back-project those with known depth to world points with the view's K and c2w. If fewer
   than ``MIN_POINTS`` grid pixels have depth, the whole grid is back-projected at the scene's
   median valid depth instead (so a view without depth still gets a sensible ranking); that
   median comes from ``scene.depth_views`` (a test scene's source pool, a train scene's views), and
   in a scene with no depth at all (a capture without depth maps) it is sqrt(near * far).
2. Query views whose depth may be used: a candidate's score is the fraction of the QUERY's points
   that land in front of the candidate camera (z > 0) and inside its image (-0.5 <= u < W - 0.5,
   -0.5 <= v < H - 0.5, the pixel-centre convention): "how much of what the query sees does this
   candidate see".
   Blind queries (:func:`blind_views`: the ``test`` split of a test scene, whose depth and labels
   are ground truth a user does not have): a candidate's score is the fraction of the CANDIDATE's
   own points that land in front of and inside the query camera: "how much of what this candidate
   saw lies in the query's frustum". It needs only the query's pose and intrinsics; the query's
   depth is never read. Both scores are scale-free and directed; occlusion is not modelled (a
   frustum overlap, not a visibility test).
3. Candidates are sorted by score (descending), ties broken by the smaller angle between optical
   axes, then the smaller camera-centre distance, then capture order. The top ``k`` are kept.

The paper's public code ranks by camera-centre distance alone; at 30 fps that returns
near-duplicate frames and, worse, cameras next to the query that look the other way. The overlap
score never prefers a camera facing away, and the loader samples m sources at random from the top
k so near duplicates are not always chosen.

Candidates come from ``scene.source_pool`` (which also measures bounds): the views a training or
evaluation tuple may use as sources (for training scenes, the ``train`` split minus held-out
``test`` views; for test scenes, ``source`` plus ``finetune``).
"""

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
    """Ranked source-view candidates of one view (best first)."""

    ids: list[str]
    """View ids, best first; never the view itself."""
    scores: list[float]
    """Overlap fraction in [0, 1] of each id, index-aligned with ``ids``."""

    def to_json(self) -> dict:
        """JSON form stored in the shards as ``<key>.neighbours.json``."""
        return {"ids": list(self.ids), "scores": [round(float(s), 6) for s in self.scores]}

    @classmethod
    def from_json(cls, d: dict) -> Neighbours:
        """Inverse of :meth:`to_json`."""
        return cls(ids=list(d["ids"]), scores=[float(s) for s in d["scores"]])


def blind_views(meta: SceneMeta) -> set[str]:
    """Views ranked without their own depth or labels: the ``test`` split of a ``test`` scene.

    At test time a user has only such a view's pose and intrinsics; its depth and labels are the
    ground truth it is scored against, so they must not choose its source views.
    """
    return set(meta.splits.get("test", [])) if meta.role == "test" else set()


def grid_samples(depth: np.ndarray, grid: tuple[int, int] = GRID) -> np.ndarray:
    """(u, v, z) rows (P, 3) of a sparse grid of pixel centres of one depth map (H, W), z in metres."""
    h, w = depth.shape
    rows = np.unique(np.clip(np.rint((np.arange(grid[0]) + 0.5) * h / grid[0] - 0.5), 0, h - 1).astype(int))
    cols = np.unique(np.clip(np.rint((np.arange(grid[1]) + 0.5) * w / grid[1] - 0.5), 0, w - 1).astype(int))
    v, u = np.meshgrid(rows, cols, indexing="ij")
    return np.stack([u.ravel(), v.ravel(), depth[v, u].ravel()], axis=1).astype(np.float64)


def fallback_depth(samples: list[np.ndarray], bounds: tuple[float, float] | None = None) -> float:
    """Median valid depth over grid samples (each (P, 3), from :func:`grid_samples`; pass those of
    ``scene.depth_views``), used where a view lacks depth. A scene without any depth (a capture converted
    without depth maps) falls back to the geometric mean of its ``bounds`` (near, far) when given."""
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


def _fractions(points: np.ndarray, proj: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """Fraction (C,) of world points (P, 3) in front of and inside each camera of ``proj`` (C, 3, 4).

    K's last row is [0, 0, 1], so the third projected coordinate is the camera z.
    """
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


def overlap_fractions(points: np.ndarray, Ks: np.ndarray, c2ws: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """Fraction (C,) of world points (P, 3) in front of and inside each of C cameras (Ks (C,3,3), c2ws (C,4,4))."""
    return _fractions(points, projection_matrices(Ks, c2ws), hw)


def _seen_by_query(points: list[np.ndarray], proj_query: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """Fraction (C,) of each candidate's own world points (C arrays (P_c, 3)) in front of and inside
    the query camera ``proj_query`` (3, 4)."""
    return np.array([_fractions(p, proj_query[None], hw)[0] for p in points])


def rank_order(capture: np.ndarray, score: np.ndarray, cos: np.ndarray, dist: np.ndarray, k: int) -> np.ndarray:
    """Positions (<= k,) of the best candidates (rule step 3): ``score`` (C,) descending (to 1e-6), ties broken
    by the larger ``cos`` (C,) between optical axes, the smaller camera-centre ``dist`` (C,), the earlier
    ``capture`` index (C,)."""
    return np.lexsort((capture, dist, -cos, -np.round(score, 6)))[:k]                 # last key sorts first


def rank_camera(K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int], c2ws: np.ndarray, points: list[np.ndarray],
                k: int) -> tuple[np.ndarray, np.ndarray]:
    """Rank C candidates in capture order for a camera no depth is known for, as a :func:`blind_views` view is.

    K (3, 3), c2w (4, 4) and ``hw``: the camera; c2ws (C, 4, 4): the candidates' poses; points: their
    :func:`grid_points` (C arrays (P_c, 3)). Returns (positions of the top ``k`` candidates, best first; their
    scores), the ranking :func:`rank_neighbours` gives a blind view.
    """
    score = _seen_by_query(points, projection_matrices(K[None], c2w[None])[0], hw)
    cos = c2ws[:, :3, 2] @ c2w[:3, 2]
    dist = np.linalg.norm(c2ws[:, :3, 3] - c2w[:3, 3], axis=1)
    order = rank_order(np.arange(len(points)), score, cos, dist, k)
    return order, score[order]


def rank_neighbours(view_ids: list[str], Ks: np.ndarray, c2ws: np.ndarray, hw: tuple[int, int],
                    points: dict[str, np.ndarray], pool: list[str], k: int) -> dict[str, Neighbours]:
    """Top-``k`` neighbours from ``pool`` for every view (see the module rule).

    view_ids: V ids; Ks (V, 3, 3); c2ws (V, 4, 4); points: world points (P_i, 3) from
    :func:`grid_points` of every view whose own depth may be used, by id. A view absent from
    ``points`` (a :func:`blind_views` view) is scored by how much of each candidate's points lies in
    its camera; every pool view needs points (ValueError otherwise).
    """
    index = {vid: i for i, vid in enumerate(view_ids)}
    cand = np.array([index[v] for v in pool])
    missing = [v for v in pool if v not in points]
    if missing:
        raise ValueError(f"pool views {missing} have no grid points; every candidate needs them (a view ranked "
                         "without its own depth is scored with its candidates' points)")
    proj = projection_matrices(Ks, c2ws)                                              # (V, 3, 4)
    axes = c2ws[:, :3, 2]                                                             # (V, 3) optical axes
    centres = c2ws[:, :3, 3]                                                          # (V, 3)
    out: dict[str, Neighbours] = {}
    for i, vid in enumerate(view_ids):
        others = cand[cand != i]
        if vid in points:
            score = _fractions(points[vid], proj[others], hw)
        else:
            score = _seen_by_query([points[view_ids[j]] for j in others], proj[i], hw)
        cos = axes[others] @ axes[i]
        dist = np.linalg.norm(centres[others] - centres[i], axis=1)
        order = rank_order(others, score, cos, dist, k)
        out[vid] = Neighbours(ids=[view_ids[j] for j in others[order]], scores=[float(s) for s in score[order]])
    return out
