"""Neighbour ranking: the top neighbour sees the most of what the query sees (checked with OpenCV)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import scene_fixtures
from hypothesis import given, settings
from hypothesis import strategies as st

from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.neighbours import (fractions_inside, grid_points, grid_samples, projection_matrices,
                                              rank_neighbours)
from sray.data_tools.shards.writer import scene_neighbours


def _opencv_fraction(points: np.ndarray, K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int]) -> float:
    """Fraction of world points (P, 3) in front of and inside a camera, via cv2.projectPoints."""
    w2c = np.linalg.inv(c2w)
    rvec, _ = cv2.Rodrigues(w2c[:3, :3])
    uv = cv2.projectPoints(points, rvec, w2c[:3, 3], K, None)[0][:, 0]              # (P, 2)
    z = points @ w2c[2, :3] + w2c[2, 3]
    h, w = hw
    inside = (z > 0) & (uv[:, 0] >= -0.5) & (uv[:, 0] < w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < h - 0.5)
    return float(inside.mean())


def _all_depth_points(depth: np.ndarray, K: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """Every pixel with depth, back-projected to world points (P, 3)."""
    v, u = np.nonzero(depth > 0)
    cam = np.stack([u, v, np.ones_like(u)], axis=1) @ np.linalg.inv(K).T * depth[v, u][:, None]
    return cam @ c2w[:3, :3].T + c2w[:3, 3]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_top_neighbour_sees_most_of_what_the_query_sees(seed: int) -> None:
    """For every view: the top neighbour is never itself and has the largest fraction (within 0.05) of the
    query's visible pixels inside its image, counted over ALL pixels with OpenCV."""
    scene = scene_fixtures.make_scene("room", n_views=12, height=48, width=64, seed=seed)
    ranked, hw = scene_neighbours(scene, k=20)
    views = {v.view_id: v for v in scene.views()}
    pool = source_pool(scene.meta)
    for query_id, view in views.items():
        points = _all_depth_points(view.depth, view.K, view.c2w)
        truth = {c: _opencv_fraction(points, views[c].K, views[c].c2w, hw) for c in pool if c != query_id}
        ids = ranked[query_id].ids
        assert query_id not in ids and sorted(ids) == sorted(truth)
        assert truth[ids[0]] >= max(truth.values()) - 0.05, (query_id, ids[0], truth)
        scores = np.array(ranked[query_id].scores)
        np.testing.assert_allclose(scores, [truth[c] for c in ids], atol=0.06)
        assert np.all(np.diff(scores) <= 0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_test_view_neighbours_are_the_candidates_that_saw_its_frustum(seed: int) -> None:
    """A test scene's test view is ranked by the fraction of each candidate's OWN visible pixels inside the
    test camera (all pixels, OpenCV); its own depth plays no part (zeroing it changes nothing)."""
    scene = scene_fixtures.make_scene("room", n_views=15, height=48, width=64, seed=seed, role="test")
    ranked, hw = scene_neighbours(scene, k=20)
    views = {v.view_id: v for v in scene.views()}
    pool = source_pool(scene.meta)
    for query_id in scene.meta.splits["test"]:
        query = views[query_id]
        truth = {c: _opencv_fraction(_all_depth_points(views[c].depth, views[c].K, views[c].c2w), query.K, query.c2w,
                                     hw) for c in pool}
        ids = ranked[query_id].ids
        assert sorted(ids) == sorted(truth) and truth[ids[0]] >= max(truth.values()) - 0.05, (query_id, ids, truth)
        np.testing.assert_allclose(ranked[query_id].scores, [truth[c] for c in ids], atol=0.06)
        views[query_id].depth = np.zeros_like(query.depth)
    assert scene_neighbours(scene, k=20)[0] == ranked


def test_overlap_beats_centre_distance() -> None:
    """The nearest camera facing away ranks last; a camera behind the query looking the same way ranks first;
    a query without depth falls back to the scene's median depth; a query without points (a test view)
    ranks the same from its candidates' points."""
    K = scene_fixtures.intrinsics(30, 40)
    origin, wall = np.array([0.0, 0.0, 1.5]), np.array([3.0, 0.0, 1.5])
    c2ws = np.stack([
        scene_fixtures.look_at(origin, wall),                                        # query
        scene_fixtures.look_at(origin + [0.0, 0.05, 0.0], origin - [3.0, 0.0, 0.0]),  # 5 cm away, facing away
        scene_fixtures.look_at(origin - [1.0, 0.0, 0.0], wall),                      # 1 m behind, same way
        scene_fixtures.look_at(origin + [0.0, 0.3, 0.0], origin + [0.3, 3.0, 0.0]),  # turned 80 degrees
    ])
    ids = ["q", "away", "behind", "turned"]
    depth = np.full((30, 40), 3.0, np.float32)
    for query_depth, fallback in ((depth, 3.0), (np.zeros_like(depth), 3.0)):
        points = {"q": grid_points(grid_samples(query_depth), K, c2ws[0], fallback)}
        points |= {v: grid_points(grid_samples(depth), K, c, fallback) for v, c in zip(ids[1:], c2ws[1:])}
        ranked = rank_neighbours(ids, np.stack([K] * 4), c2ws, (30, 40), points, ids, k=3)
        assert ranked["q"].ids == ["behind", "turned", "away"]
        assert ranked["q"].scores[0] == 1.0 and ranked["q"].scores[-1] == 0.0
    del points["q"]  # a test view of a test scene: scored by how much of each candidate's points it frames
    ranked = rank_neighbours(ids, np.stack([K] * 4), c2ws, (30, 40), points, ids[1:], k=3)
    assert ranked["q"].ids == ["behind", "turned", "away"]
    assert 0.0 < ranked["q"].scores[0] < 1.0 and ranked["q"].scores[1:] == [0.0, 0.0]
    with pytest.raises(ValueError, match="pool views \\['q'\\]"):
        rank_neighbours(ids, np.stack([K] * 4), c2ws, (30, 40), points, ids, k=3)
    by_distance = sorted(ids[1:], key=lambda i: np.linalg.norm(c2ws[ids.index(i), :3, 3] - origin))
    assert by_distance[0] == "away"  # what the centre-distance rule would have picked


def _random_camera(rng: np.random.Generator) -> np.ndarray:
    """A random rigid camera-to-world (4, 4)."""
    c2w = np.eye(4)
    c2w[:3, :3] = cv2.Rodrigues(rng.normal(size=3))[0]
    c2w[:3, 3] = rng.normal(size=3)
    return c2w


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_points=st.integers(1, 60), n_cams=st.integers(1, 5))
def test_fractions_inside_match_opencv(seed: int, n_points: int, n_cams: int) -> None:
    """The vectorised fraction equals cv2.projectPoints camera by camera (one boundary point of slack)."""
    rng = np.random.default_rng(seed)
    points = rng.normal(scale=2.0, size=(n_points, 3))
    c2ws = np.stack([_random_camera(rng) for _ in range(n_cams)])
    Ks = np.stack([scene_fixtures.intrinsics(24, 32, focal_ratio=rng.uniform(0.3, 1.5)) for _ in range(n_cams)])
    got = fractions_inside(points, projection_matrices(Ks, c2ws), (24, 32))
    want = [_opencv_fraction(points, K, c, (24, 32)) for K, c in zip(Ks, c2ws)]
    np.testing.assert_allclose(got, want, atol=1.0 / n_points + 1e-12)


def test_source_pool_follows_the_role() -> None:
    """Train scenes: train minus held-out test views; test scenes: source plus finetune; empty pools raise."""
    ids = [f"{i}" for i in range(6)]
    train = SceneMeta("a", "scannet20", [], ids, {"train": ids, "test": ["4", "5"]})
    assert source_pool(train) == ["0", "1", "2", "3"]
    test = SceneMeta("b", "scannet20", [], ids, {"source": ["2", "0"], "finetune": ["1"], "test": ["5"]}, role="test")
    assert source_pool(test) == ["0", "1", "2"]
    with pytest.raises(ValueError, match="splits"):
        source_pool(SceneMeta("c", "scannet20", [], ids, {"test": ids}, role="test"))
