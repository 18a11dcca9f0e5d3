"""Vectorised ray casting of the procedural scenes against a per-face reference written as plain loops."""

from __future__ import annotations

import math

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from sray.data_tools.synth.geometry import Box, PackedBoxes, box_normals, cast_rays, cast_shell
from sray.data_tools.synth.materials import Material

PLAIN = Material(0, (0.5, 0.5, 0.5), (0.5, 0.5, 0.5))


def _reference_hit(origin: np.ndarray, d: np.ndarray, boxes: list[Box]) -> tuple[float, int]:
    """Nearest hit by intersecting each face plane and testing the point against the face rectangle.

    Boxes that contain the origin are skipped: cast_rays documents that a camera inside a box sees
    through it (its entry lies behind the origin).
    """
    best_t, best_i = math.inf, -1
    for i, b in enumerate(boxes):
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        rel = origin - np.asarray(b.center)
        o = np.array([c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1], rel[2]])
        dl = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])
        half = np.asarray(b.size) / 2
        if np.all(np.abs(o) < half):
            continue
        for k in range(3):
            if abs(dl[k]) < 1e-12:
                continue
            for sign in (-1.0, 1.0):
                t = (sign * half[k] - o[k]) / dl[k]
                p = o + t * dl
                others = [j for j in range(3) if j != k]
                if t > 1e-4 and all(abs(p[j]) <= half[j] + 1e-9 for j in others) and t < best_t:
                    best_t, best_i = t, i
    return best_t, best_i


def _random_boxes(rng: np.random.Generator, n: int) -> list[Box]:
    boxes = []
    for _ in range(n):
        yaw = float(rng.choice([0.0, math.pi / 2, -math.pi, float(rng.uniform(-3, 3))]))
        boxes.append(Box(center=tuple(rng.uniform(-2, 2, 3)), size=tuple(rng.uniform(0.1, 1.5, 3)), label=0,
                         material=PLAIN, yaw=yaw))
    return boxes


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_slab_casting_matches_face_by_face_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    boxes = _random_boxes(rng, 6)
    packed = PackedBoxes.from_boxes(boxes)
    origin = rng.uniform(-4, 4, 3)
    dirs = rng.normal(size=(40, 3)) * rng.uniform(0.2, 3.0, (40, 1))
    t, idx = cast_rays(origin, dirs, packed, chunk=7)
    for r in range(len(dirs)):
        ref_t, ref_i = _reference_hit(origin, dirs[r], boxes)
        if math.isinf(ref_t):
            assert math.isinf(t[r]) and idx[r] == -1
        else:
            torch.testing.assert_close(torch.tensor(float(t[r]), dtype=torch.float64),
                                       torch.tensor(float(ref_t), dtype=torch.float64), rtol=1e-5, atol=1e-5)
            assert idx[r] == ref_i


def test_a_box_around_the_origin_is_seen_through() -> None:
    inner = Box(center=(0.0, 0.0, 0.0), size=(1.0, 1.0, 1.0), label=0, material=PLAIN)
    ahead = Box(center=(3.0, 0.0, 0.0), size=(1.0, 1.0, 1.0), label=0, material=PLAIN)
    t, idx = cast_rays(np.zeros(3), np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]),
                       PackedBoxes.from_boxes([inner, ahead]))
    assert idx.tolist() == [1, -1]
    assert float(t[0]) == 2.5 and math.isinf(float(t[1]))


def test_normals_point_out_of_the_hit_face() -> None:
    box = Box(center=(0.0, 0.0, 0.0), size=(2.0, 1.0, 0.5), label=0, material=PLAIN, yaw=0.3)
    packed = PackedBoxes.from_boxes([box])
    origin = np.array([5 * math.cos(0.3), 5 * math.sin(0.3), 0.0])
    t, idx = cast_rays(origin, -origin[None, :], packed)
    hit = origin + float(t[0]) * -origin
    normals, axis = box_normals(packed, idx, packed.to_local(idx, hit[None, :]))
    expected = torch.tensor([math.cos(0.3), math.sin(0.3), 0.0], dtype=torch.float64)
    torch.testing.assert_close(torch.from_numpy(normals[0]).double(), expected, rtol=0, atol=1e-6)
    assert axis[0] == 0
    torch.testing.assert_close(torch.tensor(float(t[0]), dtype=torch.float64),
                               torch.tensor(0.8, dtype=torch.float64), rtol=0, atol=1e-6)


def test_shell_exit_depth_and_face() -> None:
    room = (4.0, 3.0, 2.5)
    origin = np.array([1.0, 1.0, 1.5])
    dirs = np.array([[-1.0, 0, 0], [2.0, 0, 0], [0, -0.5, 0], [0, 1, 0], [0, 0, -1], [0.1, 0.1, 1]])
    t, face = cast_shell(origin, dirs, room)
    assert face.tolist() == [0, 1, 2, 3, 4, 5]
    torch.testing.assert_close(torch.from_numpy(t).double(),
                               torch.tensor([1.0, 1.5, 2.0, 2.0, 1.5, 1.0], dtype=torch.float64), rtol=0, atol=1e-6)


def test_quarter_turned_boxes_fold_to_axis_aligned_extents() -> None:
    box = Box(center=(1.0, 2.0, 0.5), size=(2.0, 0.5, 1.0), label=3, material=PLAIN, yaw=math.pi / 2)
    packed = PackedBoxes.from_boxes([box])
    assert packed.yaw[0] == 0.0 and packed.half[0].tolist() == [0.25, 1.0, 0.5] and packed.quarter[0] == 1
    inside = np.array([[1.2, 2.9, 0.5], [1.3, 2.0, 0.5]])
    assert packed.contains(inside).ravel().tolist() == [True, False]
