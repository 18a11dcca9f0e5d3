"""The view-weights diagnostic's geometry and figures: visibility against a hand-built source view, the ranking
score, occluded masses and relative weights against naive loops, the floor against the weight map itself."""

from __future__ import annotations

import itertools

import pytest
import torch

from sray.model.semantic_weights import radial_weights
from sray.platform.eval.label_transfer import point_hits
from sray.lab.view_weights.measure import (
    WeightTally,
    occluded_mass_bounds,
    surface_pixels,
)

F, C = 10.0, 4.5  # focal length and principal point of a 10x10 source image


def _world_point(u: float, v: float, z: float, c2w: torch.Tensor) -> torch.Tensor:
    """The world point at camera depth z on pixel (u, v) of a camera with focal F, centre (C, C) and pose c2w."""
    cam = torch.tensor([(u - C) * z / F, (v - C) * z / F, z, 1.0], dtype=torch.float64)
    return (c2w.double() @ cam)[:3]


def test_visibility_is_read_from_each_sources_depth_at_the_pixel_the_point_lands_on() -> None:
    """Source 0 sees a wall at depth 2 with a box at depth 1 over pixels u, v in 6..9; source 1 is source 0 moved
    1 m along x and sees the wall everywhere. A wall point behind the box is occluded in source 0 only; a wall
    point elsewhere is visible in both; a point in front of the wall, outside the image or behind the camera is
    neither; an unknown source depth is neither."""
    K = torch.tensor([[F, 0.0, C], [0.0, F, C], [0.0, 0.0, 1.0]]).expand(2, 3, 3)
    c2w = torch.eye(4).repeat(2, 1, 1)
    c2w[1, 0, 3] = 1.0
    depth = torch.full((2, 10, 10), 2.0)
    depth[0, 6:, 6:] = 1.0
    depth[1, 0, 0] = 0.0
    eye = torch.eye(4)
    points = torch.stack([
        _world_point(7.0, 7.0, 2.0, eye),   # behind source 0's box; in source 1 at u = 2, on the wall
        _world_point(2.0, 3.0, 2.0, eye),   # wall, visible to source 0 (u = -3 in source 1: outside)
        _world_point(8.0, 2.0, 1.5, eye),   # in front of the wall
        _world_point(30.0, 2.0, 2.0, eye),  # outside source 0's image
        torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64),  # behind both cameras
        _world_point(0.0, 0.0, 2.0, c2w[1]),  # source 1's pixel (0, 0) has no depth; source 0 sees it at u = 5
    ])
    index, visible, occluded = point_hits(points, K, c2w, (10, 10), depth, tolerance=0.05)
    assert index[:, 0].tolist() == [7 * 10 + 7, 7 * 10 + 2]  # row-major v * W + u in each source
    _, seen, hidden = point_hits(points, K, c2w, (10, 10), None, tolerance=0.05)  # no depth: no occlusion test
    assert seen.T.tolist() == [[True, True], [True, False], [True, True], [False, False], [False, False],
                               [True, True]]
    assert not hidden.any()
    visible, occluded = visible.T, occluded.T
    assert visible.tolist() == [[False, True], [True, False], [False, False], [False, False], [False, False],
                                [True, False]]
    assert occluded.tolist() == [[True, False], [False, False], [False, False], [False, False], [False, False],
                                 [False, False]]


def _random_case(seed: int, points: int = 40, m: int = 5) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Weights in C(0.7) for random logits and validity, disjoint random visible/occluded flags, some ties."""
    g = torch.Generator().manual_seed(seed)
    valid = torch.rand(points, m, generator=g) < 0.8
    logits = torch.randint(-2, 3, (points, m), generator=g).float()  # few values: ties happen
    weights = radial_weights(logits, valid, 0.7, 0.01)
    kind = torch.randint(0, 3, (points, m), generator=g)  # 0 neither, 1 visible, 2 occluded
    return weights, kind == 1, kind == 2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_tally_matches_a_naive_loop_over_points_and_views(seed: int) -> None:
    """The spread of n w, shares, mean relative weights n w, the ranking score (ties one half), occluded masses on
    mixed points and the surface accuracies, summed over two batches, equal a point-by-point loop; flags on invalid
    views are ignored."""
    weights, visible, occluded = _random_case(seed)
    correct = torch.rand(weights.shape[0], generator=torch.Generator().manual_seed(seed + 10)) < 0.5
    tally = WeightTally(0.7)
    tally.add(weights[:17], visible[:17], occluded[:17], correct[:17])
    tally.add(weights[17:], visible[17:], occluded[17:], correct[17:])
    got = tally.summary()

    rel = {"vis": [], "occ": [], "all": []}
    lower = pairs = 0.0
    mass, plain, floor, mixed, acc = [], [], [], 0, {"occ": [], "clear": []}
    for p in range(weights.shape[0]):
        w = weights[p].tolist()
        valid = [i for i in range(len(w)) if w[i] > 0]
        n = len(valid)
        vis = [i for i in valid if visible[p, i]]
        occ = [i for i in valid if occluded[p, i]]
        rel["all"] += [n * w[i] for i in valid]
        rel["vis"] += [n * w[i] for i in vis]
        rel["occ"] += [n * w[i] for i in occ]
        for i, j in itertools.product(occ, vis):
            pairs += 1
            lower += 1.0 if w[i] < w[j] else 0.5 if w[i] == w[j] else 0.0
        if occ and vis:
            mixed += 1
            mass.append(sum(w[i] for i in occ))
            plain.append(len(occ) / n)
            floor.append(max(len(occ) * 0.7 / n, 1 - (n - len(occ)) / (0.7 * n), 0.0))
        if occ:
            acc["occ"].append(bool(correct[p]))
        elif n:
            acc["clear"].append(bool(correct[p]))
    n_valid = int((weights > 0).sum())
    assert got["points"] == weights.shape[0] and got["valid_views"] == n_valid
    spread = torch.tensor(rel["all"]).double().std(correction=0).item()
    assert got["relative_weight_sd"] == pytest.approx(spread)
    assert got["visible_share"] == pytest.approx(len(rel["vis"]) / n_valid)
    assert got["occluded_share"] == pytest.approx(len(rel["occ"]) / n_valid)
    assert got["visible_relative_weight"] == pytest.approx(sum(rel["vis"]) / len(rel["vis"]))
    assert got["occluded_relative_weight"] == pytest.approx(sum(rel["occ"]) / len(rel["occ"]))
    assert got["pairs"] == pairs and got["ranking"] == pytest.approx(lower / pairs)
    assert got["mixed_points"] == mixed
    assert got["occluded_mass"] == pytest.approx(sum(mass) / mixed)
    assert got["occluded_mass_plain"] == pytest.approx(sum(plain) / mixed)
    assert got["occluded_mass_floor"] == pytest.approx(sum(floor) / mixed)
    assert got["removed_share"] == pytest.approx((sum(plain) - sum(mass)) / (sum(plain) - sum(floor)))
    assert got["acc_occluded"] == pytest.approx(sum(acc["occ"]) / len(acc["occ"]))
    assert got["acc_clear"] == pytest.approx(sum(acc["clear"]) / len(acc["clear"]))


def test_the_floor_bounds_every_weighting_and_is_what_the_weight_map_reaches() -> None:
    """For every n and n_occ, occluded mass of random weights in C(tau) never falls below the floor, and logits
    pushing the occluded views down and the others up reach it to within the map's margin."""
    tau, margin = 0.7, 1e-4
    g = torch.Generator().manual_seed(0)
    for n in range(1, 9):
        for n_occ in range(1, n):
            valid = torch.ones(256, n, dtype=torch.bool)
            occ = torch.zeros(n, dtype=torch.bool)
            occ[:n_occ] = True
            _, floor = occluded_mass_bounds(torch.tensor([n_occ]), torch.tensor([n]), tau)
            random_mass = radial_weights(8 * torch.randn(256, n, generator=g), valid, tau, margin)[:, occ].sum(1)
            assert float(random_mass.min()) >= float(floor) - 1e-6
            extreme = torch.where(occ, -1e4, 1e4)[None]
            reached = radial_weights(extreme, valid[:1], tau, margin)[:, occ].sum()
            assert float(reached) == pytest.approx(float(floor), abs=1e-3)


def test_surface_pixels_keep_labelled_pixels_with_depth_on_the_stride_grid() -> None:
    """Every stride-th row and column; pixels without depth or with the ignore label are dropped."""
    depth = torch.ones(5, 6)
    depth[0, 2] = 0.0
    label = torch.zeros(5, 6, dtype=torch.int64)
    label[2, 4] = 255
    got = surface_pixels(depth, label, 255, 2).tolist()
    assert got == [v * 6 + u for v in (0, 2, 4) for u in (0, 2, 4) if (v, u) not in ((0, 2), (2, 4))]
