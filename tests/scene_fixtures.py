"""Tiny, exactly consistent canonical scenes for tests (reusable by every engineer).

A scene is a closed box room (x, y in [-2, 2] m, z in [0, 2.5] m, z up) with a table-sized box in the
middle. Cameras stand inside the room and look in random directions; every pixel is ray-cast
analytically, so depth, colour and labels agree across views exactly (a world point has one colour
and one label whichever camera sees it). Labels use ScanNet-20 ids: walls 0, floor 1, the box
"table" 6, a "picture" patch 10 on the +x wall; the ceiling is unlabelled (IGNORE_ID).

Import from a test module with ``import scene_fixtures`` (tests/conftest.py puts tests/ on sys.path).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sray.data_tools.label_spaces import SCANNET20
from sray.data_tools.png import depth_to_png16, png16_to_depth
from sray.data_tools.scene import IGNORE_ID, Scene, SceneMeta, View, scene_depth_bounds
from sray.data_tools.scene_folder import write_dataset_index, write_scene

ROOM_LO = np.array([-2.0, -2.0, 0.0])
ROOM_HI = np.array([2.0, 2.0, 2.5])
BOX_LO = np.array([-0.4, -0.4, 0.0])
BOX_HI = np.array([0.4, 0.4, 0.8])
WALL, FLOOR, TABLE, PICTURE = 0, 1, 6, 10


def intrinsics(height: int, width: int, focal_ratio: float = 0.6) -> np.ndarray:
    """(3, 3) pinhole K with fx = fy = focal_ratio * W and a centred principal point ((W-1)/2, (H-1)/2)."""
    f = focal_ratio * width
    return np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(4, 4) camera-to-world in OpenCV axes (x right, y down, z forward) for a world with z up."""
    z = target - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, np.array([0.0, 0.0, 1.0]))
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([x, y, z], axis=1)
    c2w[:3, 3] = eye
    return c2w


def _slab(origin: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit ray parameters (N,) of rays origin + t * dirs (N, 3) through an axis box."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (lo - origin) / dirs
        t1 = (hi - origin) / dirs
    near = np.nanmax(np.minimum(t0, t1), axis=1)
    far = np.nanmin(np.maximum(t0, t1), axis=1)
    return near, far


def render(K: np.ndarray, c2w: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray-cast the room: rgb uint8 (H, W, 3), depth float32 (H, W) metres (z-depth), label uint16 (H, W)."""
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1)              # (N, 3)
    dirs = pix @ np.linalg.inv(K).T @ c2w[:3, :3].T                              # (N, 3), camera z = 1
    origin = c2w[:3, 3]
    _, t_room = _slab(origin, dirs, ROOM_LO, ROOM_HI)
    box_in, box_out = _slab(origin, dirs, BOX_LO, BOX_HI)
    hits_box = (box_in < box_out) & (box_in > 0)
    t = np.where(hits_box, box_in, t_room)
    points = origin + t[:, None] * dirs                                          # (N, 3)

    label = np.full(t.shape, WALL, np.uint16)
    label[np.abs(points[:, 2] - ROOM_LO[2]) < 1e-6] = FLOOR
    label[np.abs(points[:, 2] - ROOM_HI[2]) < 1e-6] = IGNORE_ID
    on_wall = np.abs(points[:, 0] - ROOM_HI[0]) < 1e-6
    label[on_wall & (np.abs(points[:, 1]) < 0.6) & (np.abs(points[:, 2] - 1.4) < 0.4)] = PICTURE
    label[hits_box] = TABLE

    checker = (np.floor(points[:, 0] * 4) + np.floor(points[:, 1] * 4) + np.floor(points[:, 2] * 4)) % 2
    palette = np.array([[180, 170, 150], [120, 90, 60], [200, 200, 210]], np.float64)
    base = palette[np.select([label == FLOOR, label == TABLE], [1, 2], 0)]
    base[label == PICTURE] = [40, 90, 200]
    shade = 0.75 + 0.25 * checker + 0.05 * np.sin(points @ np.array([3.1, 5.3, 7.7]))
    rgb = np.clip(base * shade[:, None], 0, 255).astype(np.uint8)
    return rgb.reshape(height, width, 3), t.reshape(height, width).astype(np.float32), label.reshape(height, width)


def random_cameras(n_views: int, seed: int) -> list[np.ndarray]:
    """A scan-like trajectory: eyes along an arc around the box, each looking roughly inward."""
    rng = np.random.default_rng(seed)
    cams = []
    for i in range(n_views):
        angle = 2 * np.pi * i / n_views + rng.uniform(-0.2, 0.2)
        eye = np.array([1.3 * np.cos(angle), 1.3 * np.sin(angle), rng.uniform(1.1, 1.7)])
        yaw = angle + np.pi + rng.uniform(-1.0, 1.0)
        pitch = rng.uniform(-0.6, 0.1)
        forward = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
        cams.append(look_at(eye, eye + forward))
    return cams


def default_splits(view_ids: list[str], role: str) -> dict[str, list[str]]:
    """``train`` scenes: train = all views, test = the last two; ``test`` scenes: the paper's 8/8/4
    source/finetune/test protocol scaled to the view count (source gets the remainder)."""
    if role == "train":
        return {"train": list(view_ids), "test": list(view_ids[-2:])}
    n = len(view_ids)
    n_test, n_ft = max(1, n // 5), max(1, (2 * n) // 5)
    return {"source": list(view_ids[: n - n_test - n_ft]), "finetune": list(view_ids[n - n_test - n_ft: n - n_test]),
            "test": list(view_ids[n - n_test:])}


def make_scene(name: str, n_views: int = 8, height: int = 30, width: int = 40, seed: int = 0,
               role: str = "train") -> Scene:
    """An in-memory canonical scene; depth is millimetre-quantised like the on-disk layout."""
    K = intrinsics(height, width)
    views = []
    for i, c2w in enumerate(random_cameras(n_views, seed)):
        rgb, depth, label = render(K, c2w, height, width)
        depth = png16_to_depth(depth_to_png16(depth))
        views.append(View(view_id=f"{i:05d}", rgb=rgb, depth=depth, label=label, K=K.copy(), c2w=c2w))
    ids = [v.view_id for v in views]
    meta = SceneMeta(name=name, label_space="scannet20", class_names=list(SCANNET20), view_ids=ids,
                     splits=default_splits(ids, role), role=role,
                     extra={"source": "tests/scene_fixtures.py", "seed": seed})
    scene = Scene.in_memory(meta, views)
    meta.near, meta.far = scene_depth_bounds(meta, lambda v: scene.read_view(v).depth)
    return scene


def write_dataset(root: Path, specs: list[tuple[str, int, str]], height: int = 30, width: int = 40,
                  seed: int = 0) -> Path:
    """Write scenes ``(name, n_views, role)`` in sray layout under ``root`` plus dataset.json."""
    for i, (name, n_views, role) in enumerate(specs):
        write_scene(make_scene(name, n_views, height, width, seed + i, role), root)
    write_dataset_index(root, [name for name, _, _ in specs])
    return root
