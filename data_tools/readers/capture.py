"""A posed capture (COLMAP or nerfstudio, parsed into :class:`CaptureFrame` lists) -> a canonical, unlabelled scene:
every ``frame_skip``-th frame, scale and bounds by ``capture_geometry``, views undistorted and resized on demand;
labels all IGNORE_ID, ``meta.labelled`` False (inference only)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sray.data_tools.label_spaces import class_names
from sray.data_tools.readers.camera_models import CaptureCamera, undistort
from sray.data_tools.readers.capture_geometry import (choose_scale, depth_ratios, measured_scale, point_bounds,
                                                      project_points)
from sray.data_tools.readers.common import read_depth_m, read_rgb8, resample_nearest, resize_rgb, scale_intrinsics
from sray.data_tools.scene import IGNORE_ID, Scene, SceneMeta, View


@dataclass(frozen=True)
class CaptureFrame:
    """One frame of a capture as its reader parsed it."""

    image: Path
    """Colour image file (8-bit PNG or JPEG)."""
    camera: CaptureCamera
    """Its camera (pinhole K, size, distortion)."""
    c2w: np.ndarray
    """float64 (4, 4) camera-to-world, OpenCV axes, capture units."""
    depth: Path | None = None
    """Depth map (16-bit PNG or .npy, ``depth_scale`` units per metre) in this camera, any resolution; None: none."""
    seen_points: np.ndarray | None = None
    """float64 (n, 3) the 3D points this frame observes (COLMAP tracks); None: every point of the capture."""


def check_rotation(c2w: np.ndarray, where: str) -> None:
    """ValueError naming ``where`` unless c2w (4, 4) is finite with an orthonormal rotation of determinant +1."""
    R = c2w[:3, :3]
    if not np.isfinite(c2w).all():
        raise ValueError(f"{where}: the pose has non-finite entries")
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-4:
        raise ValueError(f"{where}: the pose's rotation is not orthonormal (scaled or sheared); the capture is damaged")
    if np.linalg.det(R) < 0:
        raise ValueError(f"{where}: the pose's rotation has determinant -1 (one axis flipped); the capture is damaged")


def read_capture_depth(frame: CaptureFrame, depth_scale: float) -> np.ndarray:
    """Metric depth float32 (H, W) of ``frame`` in its undistorted pinhole camera at the camera's size."""
    path = frame.depth
    if path.suffix.lower() == ".npy":
        try:
            raw = np.load(path)
        except (OSError, ValueError):
            raise ValueError(f"{path}: not a readable .npy depth map") from None
        depth = np.squeeze(raw).astype(np.float32) / np.float32(depth_scale)
        if depth.ndim != 2:
            raise ValueError(f"{path}: depth must be one channel (H, W), got shape {raw.shape}")
    else:
        depth = read_depth_m(path, depth_scale)
    depth[~np.isfinite(depth) | (depth < 0)] = 0.0
    cam = frame.camera
    if depth.shape != cam.hw:
        depth = resample_nearest(depth, scale_intrinsics(cam.K, cam.hw, depth.shape), cam.K, cam.hw, 0.0)
    return undistort(depth, cam, nearest=True)


def capture_scene(frames: list[CaptureFrame], points: np.ndarray, *, src: Path, name: str, source_format: str,
                  label_space: str, size_hw: tuple[int, int] | None, frame_skip: int, depth_scale: float,
                  scale: float | None, extra: dict) -> Scene:
    """The unlabelled scene of a parsed capture: ``points`` (P, 3) in capture units, ``scale`` None: measured."""
    if frame_skip < 1:
        raise ValueError(f"frame_skip must be >= 1, got {frame_skip}")
    kept = frames[::frame_skip]
    if not kept:
        raise ValueError(f"{src}: the capture has no frame")
    for frame in kept:
        check_rotation(frame.c2w, f"{src}: frame {frame.image.name}")
    has_depth = all(f.depth is not None for f in kept)
    ratios = []
    if has_depth and len(points):
        for frame in kept:
            seen = frame.seen_points if frame.seen_points is not None else points
            ratios.append(depth_ratios(seen, frame.camera.K, frame.c2w, read_capture_depth(frame, depth_scale)))
    s, how = choose_scale(scale, measured_scale(ratios), str(src))
    near = far = 0.0  # measured from the depth maps by `sray data convert` when there are depth maps
    if not has_depth:
        depths = [project_points(f.seen_points if f.seen_points is not None else points, f.camera.K, f.c2w,
                                 f.camera.hw)[0] for f in kept]
        try:
            near, far = point_bounds(depths, s)
        except ValueError as e:
            raise ValueError(f"{src}: {e}; the capture needs 3D points or depth maps") from None
    hw = tuple(size_hw) if size_hw is not None else kept[0].camera.hw
    ids = {f"{i:06d}": frame for i, frame in enumerate(kept)}

    def read_view(view_id: str) -> View:
        """Load, undistort and resize one frame; poses in metres."""
        frame = ids[view_id]
        cam = frame.camera
        rgb = read_rgb8(frame.image)
        if rgb.shape[:2] != cam.hw:
            raise ValueError(f"{frame.image}: image is {rgb.shape[1]}x{rgb.shape[0]}, its camera says "
                             f"{cam.hw[1]}x{cam.hw[0]}; convert the capture's own images (not a downscaled copy)")
        K = scale_intrinsics(cam.K, cam.hw, hw)
        depth = np.zeros(hw, np.float32)
        if frame.depth is not None:
            depth = resample_nearest(read_capture_depth(frame, depth_scale), cam.K, K, hw, 0.0)
        c2w = frame.c2w.copy()
        c2w[:3, 3] *= s
        return View(view_id=view_id, rgb=resize_rgb(undistort(rgb, cam), hw), depth=depth,
                    label=np.full(hw, IGNORE_ID, np.uint16), K=K, c2w=c2w)

    meta = SceneMeta(name=name, label_space=label_space, class_names=class_names(label_space), view_ids=list(ids),
                     splits={}, near=near, far=far, labelled=False,
                     extra={"source_format": source_format, "source": str(src), "frame_skip": frame_skip,
                            "scale_m_per_unit": s, "scale_from": how, "n_points": int(len(points)),
                            "bounds_from": "depth maps" if has_depth else "3D points (per-view 1st/99th percentiles)",
                            "frames": {vid: str(f.image) for vid, f in ids.items()}, **extra})
    return Scene(meta=meta, read_view=read_view)
