"""Procedural scenes: geometry against independent back-projection, labels, cameras, splits."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from sray.data_tools.label_spaces import SCANNET20
from sray.data_tools.scene import IGNORE_ID, Scene, View
from sray.data_tools.splits import PROTOCOL_WINDOW as WINDOW
from sray.data_tools.synth.dataset import generate_scene, plan_scene
from sray.data_tools.synth.rooms import ROOM_TYPES
from sray.data_tools.synth.trajectory import HEIGHT_RANGE

H, W, N_VIEWS = 60, 80, 30


@pytest.fixture(scope="module")
def rendered() -> dict[str, Scene]:
    """One small in-memory scene per room type."""
    return {rt: generate_scene(f"t_{rt}", 100 + k, N_VIEWS, H, W, "train", rt) for k, rt in enumerate(ROOM_TYPES)}


@pytest.fixture(scope="module")
def scenes(rendered: dict[str, Scene]) -> dict[str, list[View]]:
    """The views of each rendered scene."""
    return {rt: list(scene.views()) for rt, scene in rendered.items()}


def backproject(view: View, K: np.ndarray | None = None) -> np.ndarray:
    """World points (H*W, 3) of every pixel centre at its z-depth (written independently of the renderer)."""
    K = view.K if K is None else K
    h, w = view.depth.shape
    points = []
    for v in range(h):
        u = np.arange(w, dtype=np.float64)
        z = view.depth[v].astype(np.float64)
        cam = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)
        points.append(cam @ view.c2w[:3, :3].T + view.c2w[:3, 3])
    return np.concatenate(points)


def project(points: np.ndarray, view: View) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, v, z) of world points (N, 3) in a view."""
    w2c = np.linalg.inv(view.c2w)
    cam = points @ w2c[:3, :3].T + w2c[:3, 3]
    z = cam[:, 2]
    return view.K[0, 0] * cam[:, 0] / z + view.K[0, 2], view.K[1, 1] * cam[:, 1] / z + view.K[1, 2], z


def mutual(va: View, vb: View, subpixel: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels of va seen by vb: (flat index in va, row in vb, column in vb) of mutually visible pixels.

    Mutual visibility: the point lands in vb within ``subpixel`` of a pixel centre, in front of vb,
    and its depth in vb agrees with vb's depth there within 1 % + 5 mm.
    """
    u, v, z = project(backproject(va), vb)
    ui, vi = np.rint(u).astype(int), np.rint(v).astype(int)
    h, w = vb.depth.shape
    ok = (z > 0) & (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
    ok &= (np.abs(u - ui) <= subpixel) & (np.abs(v - vi) <= subpixel)
    idx = np.flatnonzero(ok)
    seen = np.abs(vb.depth[vi[idx], ui[idx]] - z[idx]) < 0.01 * z[idx] + 0.005
    return idx[seen], vi[idx][seen], ui[idx][seen]


def test_reprojected_labels_agree_in_neighbouring_views(scenes: dict[str, list[View]]) -> None:
    for room_type, views in scenes.items():
        total = same = 0
        for i in range(0, N_VIEWS - 1, 2):
            idx, r, c = mutual(views[i], views[i + 1])
            total += len(idx)
            same += int(np.sum(views[i].label.reshape(-1)[idx] == views[i + 1].label[r, c]))
        assert total > 0.5 * (N_VIEWS // 2) * H * W, f"{room_type}: neighbouring views barely overlap"
        assert same / total >= 0.99, f"{room_type}: only {same / total:.4f} of mutually visible labels agree"


def test_surface_colour_is_view_independent(scenes: dict[str, list[View]]) -> None:
    """The same surface point (landing within 0.1 px of a pixel centre) has the same colour in both views."""
    for room_type in ("bedroom", "kitchen"):
        views = scenes[room_type]
        diffs = []
        for i in range(0, N_VIEWS - 1, 2):
            idx, r, c = mutual(views[i], views[i + 1], subpixel=0.1)
            a = views[i].rgb.reshape(-1, 3)[idx].astype(int)
            diffs.append(np.abs(a - views[i + 1].rgb[r, c].astype(int)).max(axis=1))
        d = np.concatenate(diffs)
        assert len(d) > 200
        assert np.median(d) <= 1 and np.percentile(d, 90) <= 4, f"{room_type}: colour differs across views"


def test_floor_pixels_back_project_onto_the_floor_plane(scenes: dict[str, list[View]]) -> None:
    for room_type, views in scenes.items():
        heights = np.concatenate([backproject(v)[v.label.reshape(-1) == 1, 2] for v in views[::5]])
        assert heights.size > 500
        median = torch.tensor(float(np.median(np.abs(heights))), dtype=torch.float64)
        torch.testing.assert_close(median, torch.tensor(0.0, dtype=torch.float64), rtol=0, atol=1e-3)
        # the check is sensitive: a half-pixel shift of the principal point moves the floor by millimetres
        view = max(views, key=lambda v: int(np.sum(v.label == 1)))
        shifted = view.K.copy()
        shifted[:2, 2] += 0.5
        wrong = backproject(view, shifted)[view.label.reshape(-1) == 1, 2]
        assert np.median(np.abs(wrong)) > 2e-3, room_type


def test_ceiling_is_ignored_and_labels_are_scannet20(rendered: dict[str, Scene],
                                                     scenes: dict[str, list[View]]) -> None:
    present: set[int] = set()
    for room_type, views in scenes.items():
        lx, ly, lz = rendered[room_type].meta.extra["room_size_m"]
        for v in views[::3]:
            values = set(np.unique(v.label).tolist())
            assert values <= set(range(len(SCANNET20))) | {IGNORE_ID}
            present |= values
            x, y, z = backproject(v).T
            on_ceiling = (np.abs(z - lz) < 1e-4) & (np.minimum(x, lx - x) > 0.01) & (np.minimum(y, ly - y) > 0.01)
            assert np.all(v.label.reshape(-1)[on_ceiling] == IGNORE_ID), room_type
    classes = present - {IGNORE_ID}
    assert len(classes) >= 10, f"only {sorted(SCANNET20[i] for i in classes)}"


@pytest.mark.parametrize("room_type", ROOM_TYPES)
def test_cameras_stay_inside_the_room_and_outside_furniture(room_type: str) -> None:
    plan = plan_scene(7, 60, room_type)
    lx, ly, _ = plan.room.size
    centres = plan.poses[:, :3, 3]
    assert np.all((centres[:, :2] > 0.3) & (centres[:, :2] < np.array([lx, ly]) - 0.3))
    lo, hi = HEIGHT_RANGE
    assert np.all((centres[:, 2] >= lo - 1e-9) & (centres[:, 2] <= hi + 1e-9))
    for box in plan.room.boxes:
        c, s = math.cos(box.yaw), math.sin(box.yaw)
        rel = centres - np.asarray(box.center)
        local = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1], rel[:, 2]], axis=1)
        assert not np.any(np.all(np.abs(local) < np.asarray(box.size) / 2 + 0.1, axis=1)), box.label
    for c2w in plan.poses:
        torch.testing.assert_close(torch.tensor(c2w[:3, :3].T @ c2w[:3, :3]), torch.eye(3, dtype=torch.float64),
                                   rtol=0, atol=1e-9)
        assert np.linalg.det(c2w[:3, :3]) > 0
    axes = plan.poses[:, :3, 2]
    turn = np.degrees(np.arccos(np.clip(np.sum(axes[1:] * axes[:-1], axis=1), -1, 1)))
    step = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert turn.max() < 12 and step.max() < 0.2, "consecutive views must overlap strongly"


def test_intrinsics_follow_the_pixel_centre_convention(scenes: dict[str, list[View]]) -> None:
    K = scenes["office"][0].K
    assert K[0, 2] == (W - 1) / 2 and K[1, 2] == (H - 1) / 2 and K[0, 0] == K[1, 1]
    hfov = math.degrees(2 * math.atan(W / (2 * K[0, 0])))
    assert 60 <= hfov <= 70
    view = scenes["office"][0]
    assert view.rgb.dtype == np.uint8 and view.depth.dtype == np.float32 and view.label.dtype == np.uint16
    assert np.all(view.depth > 0)


def test_test_scene_splits_follow_the_protocol() -> None:
    scene = generate_scene("t_test", 3, 26, 24, 32, "test", "office")
    splits, ids = scene.meta.splits, scene.meta.view_ids
    assert [len(splits[k]) for k in ("source", "finetune", "test")] == [8, 8, 4]
    chosen = splits["source"] + splits["finetune"] + splits["test"]
    assert len(set(chosen)) == 20
    positions = sorted(ids.index(v) for v in chosen)
    assert positions == list(range(positions[0], positions[0] + WINDOW)), "views must form a contiguous window"
    for v in splits["test"]:
        i = ids.index(v)
        assert ids[i - 1] in splits["source"] and ids[i + 1] in splits["source"]
    assert scene.meta.role == "test" and 0 < scene.meta.near < scene.meta.far


def test_train_scene_splits_hold_out_validation_views() -> None:
    scene = generate_scene("t_train", 4, 45, 24, 32, "train", "kitchen")
    train, held = scene.meta.splits["train"], scene.meta.splits["test"]
    assert held == ["00010", "00030"] and set(train) | set(held) == set(scene.meta.view_ids)
    assert not set(train) & set(held)


def test_bad_arguments_name_the_fix() -> None:
    with pytest.raises(ValueError, match="at least 20 views"):
        generate_scene("x", 0, 10, 24, 32, "test")
    with pytest.raises(ValueError, match="role"):
        generate_scene("x", 0, 25, 24, 32, "val")
