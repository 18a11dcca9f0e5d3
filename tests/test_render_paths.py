"""Camera paths of ``sray render``: SLERP, the spline and the orbit against hand-computed poses; nerfstudio's
camera_path.json read into OpenCV poses, with every bad file refused in one line naming the file and field; a
frame's camera ranked for sources as the shards rank a held-out test view."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scene_fixtures import make_scene

from sray.data_tools.scene import source_pool
from sray.data_tools.shards.neighbours import fallback_depth, grid_points, grid_samples, rank_camera, rank_neighbours
from sray.platform.render.camera_paths import TURN_METRES_PER_RADIAN, key_times, look_at, orbit_path, spline_path
from sray.platform.render.nerfstudio_path import read_camera_path
from sray.platform.render.rotations import (
    matrix_to_quaternion,
    quaternion_to_matrix,
    rigid_problem,
    rotation_angle,
    slerp,
)


def rot_z(degrees: float) -> np.ndarray:
    """(3, 3) rotation by ``degrees`` about the z axis, written out by hand."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def pose(rotation: np.ndarray, centre: tuple[float, float, float]) -> np.ndarray:
    """(4, 4) camera-to-world from a rotation and a camera centre."""
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, centre
    return out


def random_rotations(n: int, seed: int) -> list[np.ndarray]:
    """``n`` random proper rotations (QR of Gaussian matrices, signs fixed), plus a half turn (trace -1)."""
    rng = np.random.default_rng(seed)
    out = [np.diag([1.0, -1.0, -1.0])]
    for _ in range(n):
        q, r = np.linalg.qr(rng.normal(size=(3, 3)))
        q = q * np.sign(np.diag(r))
        out.append(q if np.linalg.det(q) > 0 else -q)
    return out


def assert_rigid(poses: np.ndarray) -> None:
    """Every pose (N, 4, 4) has an orthonormal rotation with determinant +1 and the row (0, 0, 0, 1)."""
    for m in poses:
        np.testing.assert_allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-12)
        assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_array_equal(m[3], [0.0, 0.0, 0.0, 1.0])


def test_quaternions_round_trip_every_rotation() -> None:
    for r in random_rotations(50, seed=0):
        q = matrix_to_quaternion(r)
        assert np.linalg.norm(q) == pytest.approx(1.0) and q[0] >= 0
        np.testing.assert_allclose(quaternion_to_matrix(q), r, atol=1e-12)
    np.testing.assert_allclose(matrix_to_quaternion(rot_z(90)), [math.sqrt(0.5), 0, 0, math.sqrt(0.5)], atol=1e-15)


def test_slerp_keeps_a_constant_angular_speed_and_hits_its_ends() -> None:
    q0, q1 = matrix_to_quaternion(np.eye(3)), matrix_to_quaternion(rot_z(120))
    t = np.linspace(0.0, 1.0, 7)
    rotations = [quaternion_to_matrix(q) for q in slerp(q0, q1, t)]
    np.testing.assert_allclose(rotations[0], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(rotations[-1], rot_z(120), atol=1e-12)
    for fraction, r in zip(t, rotations):  # about z, by 120 degrees times the fraction
        np.testing.assert_allclose(r, rot_z(120 * fraction), atol=1e-12)
    steps = [rotation_angle(a, b) for a, b in zip(rotations, rotations[1:])]
    np.testing.assert_allclose(steps, math.radians(20), atol=1e-9)
    # the shorter arc: q1 and -q1 are one rotation
    np.testing.assert_allclose(slerp(q0, -q1, t), slerp(q0, q1, t), atol=1e-12)


def test_spline_between_two_cameras_moves_and_turns_evenly() -> None:
    start, end = pose(np.eye(3), (0.0, 0.0, 0.0)), pose(rot_z(90), (2.0, 0.0, 0.0))
    path = spline_path(np.stack([start, end]), 5)
    np.testing.assert_array_equal(path[0], start)
    np.testing.assert_array_equal(path[-1], end)
    for i, s in enumerate(np.linspace(0.0, 1.0, 5)):  # end velocities are the chord's: a straight, even line
        np.testing.assert_allclose(path[i], pose(rot_z(90 * s), (2.0 * s, 0.0, 0.0)), atol=1e-12)
    assert_rigid(path)


def test_spline_through_three_cameras_matches_the_hermite_curve_by_hand() -> None:
    keys = np.stack([pose(np.eye(3), p) for p in [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0)]])
    path = spline_path(keys, 5)  # key times 0, 1, 2; frames at 0, 0.5, 1, 1.5, 2
    # velocities: (1, 0, 0) at the start, (0.5, 0.5, 0) at the corner, (0, 1, 0) at the end;
    # at s = 0.5 a Hermite segment is p0/2 + v0/8 + p1/2 - v1/8
    expected = [(0.0, 0.0, 0.0), (0.5625, -0.0625, 0.0), (1.0, 0.0, 0.0), (1.0625, 0.4375, 0.0), (1.0, 1.0, 0.0)]
    np.testing.assert_allclose(path[:, :3, 3], expected, atol=1e-12)
    np.testing.assert_allclose(path[:, :3, :3], np.broadcast_to(np.eye(3), (5, 3, 3)), atol=1e-12)


def test_spline_through_many_cameras_stays_rigid_and_ends_on_them() -> None:
    rotations = random_rotations(6, seed=1)
    rng = np.random.default_rng(2)
    keys = np.stack([pose(r, tuple(rng.uniform(-1, 1, 3))) for r in rotations])
    keys = np.concatenate([keys[:3], keys[2:3], keys[3:]])  # a repeated camera counts once
    path = spline_path(keys, 40)
    assert_rigid(path)
    np.testing.assert_array_equal(path[0], keys[0])
    np.testing.assert_array_equal(path[-1], keys[-1])
    for key in keys:  # every key camera lies on the path's curve: some frame is near it
        assert np.linalg.norm(path[:, :3, 3] - key[:3, 3], axis=1).min() < 0.5


def test_key_times_count_a_turn_as_distance() -> None:
    keys = np.stack([pose(np.eye(3), (0, 0, 0)), pose(rot_z(90), (0, 0, 0)), pose(rot_z(90), (1, 0, 0))])
    turn = TURN_METRES_PER_RADIAN * math.pi / 2
    np.testing.assert_allclose(key_times(keys), [0.0, turn, turn + 1.0], atol=1e-12)
    path = spline_path(keys, 9)
    frame_t = np.linspace(0.0, turn + 1.0, 9)
    for m, t in zip(path, frame_t):  # while turning, the rotation follows SLERP in time
        if t <= turn:
            np.testing.assert_allclose(m[:3, :3], rot_z(90 * t / turn), atol=1e-12)


def test_orbit_circles_the_cameras_centre_at_their_height_and_radius_looking_at_it() -> None:
    centre, radius, height = np.array([1.0, -2.0, 1.5]), 2.0, 1.5
    eyes = [centre + radius * np.array([math.cos(a), math.sin(a), 0.0]) for a in 0.3 + np.arange(4) * math.pi / 2]
    # level cameras looking past the centre (image up = world z), so their mean up is z
    cameras = np.stack([look_at(e, centre + np.array([0.2, -0.1, 0.0]), np.array([0.0, 0.0, 1.0])) for e in eyes])
    path = orbit_path(cameras, 8)
    assert_rigid(path)
    flat = path[:, :2, 3] - centre[:2]
    np.testing.assert_allclose(np.linalg.norm(flat, axis=1), radius, atol=1e-9)
    np.testing.assert_allclose(path[:, 2, 3], height, atol=1e-9)
    to_centre = centre - path[:, :3, 3]
    np.testing.assert_allclose(path[:, :3, 2], to_centre / np.linalg.norm(to_centre, axis=1, keepdims=True),
                               atol=1e-9)
    assert (path[:, 2, 1] < -0.99).all()  # image y (down) points down the world's z (up)
    np.testing.assert_allclose(np.arctan2(flat[0, 1], flat[0, 0]), 0.3, atol=1e-9)  # starts by the first camera
    angles = np.unwrap(np.arctan2(flat[:, 1], flat[:, 0]))
    np.testing.assert_allclose(np.diff(angles), 2 * math.pi / 8, atol=1e-9)  # counter-clockwise, evenly


def test_orbit_refuses_cameras_on_one_vertical_line() -> None:
    cameras = np.stack([look_at(np.array([0.0, 0.0, z]), np.array([1.0, 0.0, z]), np.array([0.0, 0.0, 1.0]))
                        for z in (1.0, 2.0)])
    with pytest.raises(ValueError, match="no radius"):
        orbit_path(cameras, 4)


# ---------------------------------------------------------------------------------------- nerfstudio files
GL_POSE = [0.0, 0.0, 1.0, 1.0,
           1.0, 0.0, 0.0, 2.0,
           0.0, 1.0, 0.0, 3.0,
           0.0, 0.0, 0.0, 1.0]
"""Row-major OpenGL camera-to-world: camera x along world y, camera y (up) along world z, camera z (backward)
along world x, centre (1, 2, 3). So the camera looks along world -x, world z up."""
CV_POSE = np.array([[0.0, 0.0, -1.0, 1.0],
                    [1.0, 0.0, 0.0, 2.0],
                    [0.0, -1.0, 0.0, 3.0],
                    [0.0, 0.0, 0.0, 1.0]])
"""The same camera in OpenCV axes, by hand: x stays, y (down) = -world z, z (forward) = -world x."""


def write_path_file(folder: Path, frames: list[dict] | None = None, **top: object) -> Path:
    """A camera_path.json in nerfstudio's layout (one frame of :data:`GL_POSE` by default)."""
    doc = {"camera_type": "perspective", "render_height": 240, "render_width": 320, "fps": 24, "seconds": 1,
           "camera_path": frames if frames is not None else [{"camera_to_world": GL_POSE, "fov": 60, "aspect": 4 / 3}]}
    doc.update(top)
    path = folder / "camera_path.json"
    path.write_text(json.dumps({k: v for k, v in doc.items() if v is not None}))
    return path


def test_a_nerfstudio_file_maps_to_the_opencv_pose_and_focal_length_by_hand(tmp_path: Path) -> None:
    cameras, fps = read_camera_path(write_path_file(tmp_path))
    assert fps == 24.0 and cameras.hw == (240, 320) and len(cameras) == 1
    np.testing.assert_allclose(cameras.c2w[0], CV_POSE, atol=0)
    f = 120.0 / math.tan(math.radians(30.0))  # (H / 2) / tan(fov / 2) with fov = 60 degrees
    np.testing.assert_allclose(cameras.K[0], [[f, 0, 159.5], [0, f, 119.5], [0, 0, 1]], rtol=1e-12)
    smaller, _ = read_camera_path(write_path_file(tmp_path), size_hw=(120, 160))
    assert smaller.hw == (120, 160)
    assert smaller.K[0, 0, 0] == pytest.approx(60.0 / math.tan(math.radians(30.0)))


def _scaled(factor: float) -> list[float]:
    """:data:`GL_POSE` with its rotation block scaled by ``factor``."""
    out = list(GL_POSE)
    for i in (0, 1, 2, 4, 5, 6, 8, 9, 10):
        out[i] *= factor
    return out


def _reflected() -> list[float]:
    """:data:`GL_POSE` with its rotation negated (orthonormal, determinant -1)."""
    out = list(GL_POSE)
    out[2], out[4], out[9] = -1.0, -1.0, -1.0  # rotation columns negated: determinant -1
    return out


@pytest.mark.parametrize("frames, top, field", [
    (None, {"camera_path": None}, "'camera_path'"),
    (None, {"render_height": None}, "'render_height'"),
    ([{"fov": 60}], {}, "'camera_path[0].camera_to_world'"),
    ([{"camera_to_world": GL_POSE, "fov": 60}, {"camera_to_world": GL_POSE}], {}, "'camera_path[1].fov'"),
    ([{"camera_to_world": GL_POSE[:15], "fov": 60}], {}, "'camera_path[0].camera_to_world'"),
    ([{"camera_to_world": _scaled(1.5), "fov": 60}], {}, "not orthonormal"),
    ([{"camera_to_world": _reflected(), "fov": 60}], {}, "determinant"),
    ([{"camera_to_world": GL_POSE, "fov": 200}], {}, "'camera_path[0].fov'"),
    (None, {"camera_type": "fisheye"}, "'camera_type'"),
    (None, {"fps": -1}, "'fps'"),
])
def test_bad_nerfstudio_files_are_refused_in_one_line(tmp_path: Path, frames: list[dict] | None, top: dict,
                                                      field: str) -> None:
    path = write_path_file(tmp_path, frames, **top)
    with pytest.raises(ValueError) as err:
        read_camera_path(path)
    message = str(err.value)
    assert str(path) in message and field in message and "\n" not in message


def test_a_file_that_is_not_json_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "camera_path.json"
    path.write_text("{not json")
    with pytest.raises(ValueError, match="not a readable JSON file"):
        read_camera_path(path)


def test_rigid_problem_names_what_is_wrong() -> None:
    assert rigid_problem(CV_POSE) is None
    bent = CV_POSE.copy()
    bent[3, 0] = 0.5
    assert "last row" in rigid_problem(bent)
    assert "non-finite" in rigid_problem(np.full((4, 4), np.nan))


def test_a_camera_is_ranked_as_the_shards_rank_a_test_view() -> None:
    """``rank_camera`` (a frame's sources) gives a held-out test view the ranking ``rank_neighbours`` stored."""
    scene = make_scene("room", n_views=20, role="test")
    meta, views = scene.meta, {v.view_id: v for v in scene.views()}
    pool, hw = source_pool(meta), views[meta.view_ids[0]].hw
    samples = {v: grid_samples(views[v].depth) for v in pool}
    fallback = fallback_depth(list(samples.values()))
    points = {v: grid_points(samples[v], views[v].K, views[v].c2w, fallback) for v in pool}
    ranked = rank_neighbours(meta.view_ids, np.stack([views[v].K for v in meta.view_ids]),
                             np.stack([views[v].c2w for v in meta.view_ids]), hw, points, pool, 6)
    for query in meta.splits["test"]:
        order, scores = rank_camera(views[query].K, views[query].c2w, hw, np.stack([views[v].c2w for v in pool]),
                                    [points[v] for v in pool], 6)
        assert [pool[i] for i in order] == ranked[query].ids
        np.testing.assert_allclose(scores, ranked[query].scores, atol=1e-6)
