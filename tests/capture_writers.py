"""Test helpers: write a canonical scene out as a capture (nerfstudio transforms.json, COLMAP text or binary model).

Each writer stores the scene's colour losslessly (PNG) at its own size, its cameras in the format's conventions
(nerfstudio: OpenGL camera-to-world, principal point +0.5; COLMAP: world-to-camera quaternion and translation,
principal point +0.5) and positions in capture units (metres / ``scale``), so that importing the folder with
``--scale scale`` gives back the scene's cameras. ``points_of`` makes the 3D points a capture holds: exact surface
points each view sees (scenes of ``scene_fixtures.make_scene``), with optional noise. ``mistake`` plants one
convention error for the tests that prove the comparison catches it: ``"opencv-axes"`` (nerfstudio matrices left in
OpenCV axes), ``"transposed"`` (COLMAP rotation stored camera-to-world), ``"pixel-centre"`` (principal point
without the +0.5).
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import cv2
import numpy as np
from scene_fixtures import render

from sray.data_tools.atomic import atomic_write_bytes
from sray.data_tools.png import depth_to_png16, encode_png
from sray.data_tools.scene import Scene

OPENGL_FLIP = np.diag([1.0, -1.0, -1.0, 1.0])


def rotation_to_qvec(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (3, 3), w >= 0 (from the largest diagonal term)."""
    m = np.asarray(R, np.float64)
    trace = np.trace(m)
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0] * 4
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q = np.array(q)
    return q * np.sign(q[0]) if q[0] != 0 else q


def points_of(scene: Scene, noise: float = 0.0, seed: int = 0) -> list[np.ndarray]:
    """Per view, world points (n, 3) in metres on the surfaces it sees, as structure-from-motion finds them: the
    exact ray-cast depth of ``scene_fixtures.render`` at the pixel centres of a 3x finer grid (so no point sits on
    a stored pixel centre or carries the stored depth's millimetre rounding), every 4th row and column, each
    point's distance from the camera multiplied by 1 + N(0, ``noise``)."""
    rng = np.random.default_rng(seed)
    out = []
    for view in scene.views():
        fine = (3 * view.hw[0], 3 * view.hw[1])
        K = view.K.copy()
        K[:2] *= 3.0
        K[:2, 2] += 1.0  # c' = 3 (c + 0.5) - 0.5: the pixel-centre rule
        _, depth, _ = render(K, view.c2w, *fine)
        v, u = np.mgrid[1:fine[0]:4, 1:fine[1]:4]
        z = depth[v, u].astype(np.float64) * (1.0 + noise * rng.standard_normal(v.shape))
        pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1)
        cam = pix @ np.linalg.inv(K).T * z.ravel()[:, None]
        out.append(cam @ view.c2w[:3, :3].T + view.c2w[:3, 3])
    return out


def _units(c2w: np.ndarray, scale: float) -> np.ndarray:
    """A camera-to-world with its position in capture units."""
    out = np.array(c2w, np.float64)
    out[:3, 3] /= scale
    return out


def write_ply(path: Path, points: np.ndarray, binary: bool = True) -> None:
    """A PLY of vertices x y z (float64 binary little-endian, or ASCII)."""
    header = (f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\nelement vertex {len(points)}\n"
              "property double x\nproperty double y\nproperty double z\nend_header\n").encode()
    body = np.asarray(points, "<f8").tobytes() if binary else \
        "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in points).encode()
    atomic_write_bytes(path, header + body)


def distort_image(rgb: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """What a lens with OpenCV radial-tangential ``dist`` (k1, k2, p1, p2, k3) records of the pinhole image ``rgb``
    (H, W, 3) of K: each distorted pixel samples (bilinear) the pinhole image where ``cv2.undistortPoints`` sends it."""
    h, w = rgb.shape[:2]
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    pts = np.stack([u.ravel(), v.ravel()], axis=1)[:, None, :]
    ideal = cv2.undistortPoints(pts, K, dist, P=K).reshape(h, w, 2).astype(np.float32)
    return cv2.remap(rgb, ideal[..., 0], ideal[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def write_nerfstudio(scene: Scene, dst: Path, scale: float = 1.0, depth: bool = False, ply: bool = False,
                     mistake: str = "", point_noise: float = 0.0, distortion: tuple[float, ...] = ()) -> Path:
    """``scene`` as a nerfstudio capture under ``dst`` (shared intrinsics of the first view; depth as 16-bit mm PNGs
    and the points (:func:`points_of` with ``point_noise``) as ``sparse_pc.ply`` on request; ``distortion`` (k1, k2,
    p1, p2, k3): images recorded through that OPENCV lens, :func:`distort_image`)."""
    dst = Path(dst)
    frames, K = [], None
    dist = np.array(distortion or (0.0,) * 5, np.float64)
    for i, view in enumerate(scene.views()):
        K = view.K if K is None else K
        rgb = distort_image(view.rgb, view.K, dist) if distortion else view.rgb
        atomic_write_bytes(dst / "images" / f"frame_{i:05d}.png", encode_png(rgb))
        c2w = _units(view.c2w, scale)
        frame = {"file_path": f"images/frame_{i:05d}.png",
                 "transform_matrix": (c2w if mistake == "opencv-axes" else c2w @ OPENGL_FLIP).tolist()}
        if depth:
            atomic_write_bytes(dst / "depth" / f"frame_{i:05d}.png", encode_png(depth_to_png16(view.depth)))
            frame["depth_file_path"] = f"depth/frame_{i:05d}.png"
        frames.append(frame)
    shift = 0.0 if mistake == "pixel-centre" else 0.5
    h, w = scene.read_view(scene.meta.view_ids[0]).hw
    data = {"camera_model": "OPENCV", "fl_x": K[0, 0], "fl_y": K[1, 1], "cx": K[0, 2] + shift, "cy": K[1, 2] + shift,
            "w": w, "h": h, "k1": dist[0], "k2": dist[1], "p1": dist[2], "p2": dist[3], "k3": dist[4],
            "frames": frames}
    if ply:
        write_ply(dst / "sparse_pc.ply", np.concatenate(points_of(scene, point_noise)) / scale)
        data["ply_file_path"] = "sparse_pc.ply"
    atomic_write_bytes(dst / "transforms.json", json.dumps(data, indent=1).encode())
    return dst


def _colmap_records(scene: Scene, scale: float, mistake: str) -> tuple[list, list, list]:
    """(cameras, images, points) rows: one PINHOLE camera per view; image i observes the points made from it."""
    cameras, images, points = [], [], []
    shift = 0.0 if mistake == "pixel-centre" else 0.5
    per_view = points_of(scene)
    next_id = 1
    for i, view in enumerate(scene.views()):
        K = view.K
        h, w = view.hw
        cameras.append((i + 1, 1, w, h, [K[0, 0], K[1, 1], K[0, 2] + shift, K[1, 2] + shift]))
        c2w = _units(view.c2w, scale)
        R = c2w[:3, :3].T  # world-to-camera
        t = -R @ c2w[:3, 3]
        q = rotation_to_qvec(R.T if mistake == "transposed" else R)
        ids = list(range(next_id, next_id + len(per_view[i])))
        next_id += len(ids)
        xys = [(float(u), float(v)) for u, v in np.zeros((len(ids), 2))]
        images.append((i + 1, q, t, i + 1, f"frame_{i:05d}.png", xys, ids))
        points += [(pid, p / scale, i + 1, k) for k, (pid, p) in enumerate(zip(ids, per_view[i]))]
    return cameras, images, points


def write_colmap(scene: Scene, dst: Path, scale: float = 1.0, binary: bool = False, mistake: str = "") -> Path:
    """``scene`` as a COLMAP capture: ``dst/images/`` and ``dst/sparse/0/`` in text or binary form."""
    dst = Path(dst)
    for i, view in enumerate(scene.views()):
        atomic_write_bytes(dst / "images" / f"frame_{i:05d}.png", encode_png(view.rgb))
    cameras, images, points = _colmap_records(scene, scale, mistake)
    model = dst / "sparse" / "0"
    if binary:
        cam = struct.pack("<Q", len(cameras)) + b"".join(
            struct.pack("<iiQQ", cid, mid, w, h) + struct.pack(f"<{len(p)}d", *p) for cid, mid, w, h, p in cameras)
        img = struct.pack("<Q", len(images))
        for iid, q, t, cid, name, xys, ids in images:
            img += struct.pack("<i7di", iid, *q, *t, cid) + name.encode() + b"\0" + struct.pack("<Q", len(ids))
            img += b"".join(struct.pack("<ddq", x, y, pid) for (x, y), pid in zip(xys, ids))
        pts = struct.pack("<Q", len(points)) + b"".join(
            struct.pack("<QdddBBBd", pid, *p, 128, 128, 128, 0.5) + struct.pack("<Q", 1) + struct.pack("<ii", iid, k)
            for pid, p, iid, k in points)
        for name, data in (("cameras.bin", cam), ("images.bin", img), ("points3D.bin", pts)):
            atomic_write_bytes(model / name, data)
        return dst
    models = {1: "PINHOLE"}
    cam = "# Camera list\n" + "".join(f"{cid} {models[mid]} {w} {h} " + " ".join(f"{v:.17g}" for v in p) + "\n"
                                      for cid, mid, w, h, p in cameras)
    img = "# Image list with two lines of data per image\n"
    for iid, q, t, cid, name, xys, ids in images:
        img += f"{iid} " + " ".join(f"{v:.17g}" for v in [*q, *t]) + f" {cid} {name}\n"
        img += " ".join(f"{x:.17g} {y:.17g} {pid}" for (x, y), pid in zip(xys, ids)) + "\n"
    pts = "# 3D point list\n" + "".join(f"{pid} " + " ".join(f"{v:.17g}" for v in p) + f" 128 128 128 0.5 {iid} {k}\n"
                                        for pid, p, iid, k in points)
    for name, text in (("cameras.txt", cam), ("images.txt", img), ("points3D.txt", pts)):
        atomic_write_bytes(model / name, text.encode())
    return dst
