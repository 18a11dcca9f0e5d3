"""Camera models of captures (COLMAP, nerfstudio) -> a pinhole K plus OpenCV distortion, and undistortion
(docs/capture.md). Captures centre pixel (u, v) at (u + 0.5, v + 0.5), sray at (u, v): ``c_sray = c - 0.5``.
COLMAP parameter orders (``src/colmap/sensor/models.h``): SIMPLE_PINHOLE f cx cy; PINHOLE fx fy cx cy;
SIMPLE_RADIAL f cx cy k; RADIAL f cx cy k1 k2; OPENCV fx fy cx cy k1 k2 p1 p2; OPENCV_FISHEYE fx fy cx cy
k1 k2 k3 k4; FULL_OPENCV fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

COLMAP_MODELS: dict[int, tuple[str, int]] = {
    0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5), 4: ("OPENCV", 8),
    5: ("OPENCV_FISHEYE", 8), 6: ("FULL_OPENCV", 12), 7: ("FOV", 5), 8: ("SIMPLE_RADIAL_FISHEYE", 4),
    9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12)}
"""COLMAP model id -> (name, parameter count); the binary model stores the id, the text model the name."""

_COLMAP_OPENCV: dict[str, Callable[[list[float]], tuple[list[float], list[float], bool]]] = {
    "SIMPLE_PINHOLE": lambda p: ([p[0], p[0], p[1], p[2]], [], False),
    "PINHOLE": lambda p: (p, [], False),
    "SIMPLE_RADIAL": lambda p: ([p[0], p[0], p[1], p[2]], [p[3], 0.0, 0.0, 0.0], False),
    "RADIAL": lambda p: ([p[0], p[0], p[1], p[2]], [p[3], p[4], 0.0, 0.0], False),
    "OPENCV": lambda p: (p[:4], p[4:8], False),
    "FULL_OPENCV": lambda p: (p[:4], p[4:12], False),
    "OPENCV_FISHEYE": lambda p: (p[:4], p[4:8], True),
}
"""COLMAP models OpenCV can undistort -> (fx fy cx cy, OpenCV distortion, fisheye) of their parameters."""


@dataclass(frozen=True)
class CaptureCamera:
    """One capture camera, ready for sray: pinhole intrinsics, its size and the distortion to remove."""

    K: np.ndarray
    """float64 (3, 3) pinhole intrinsics of the (width x height) image, sray's pixel-centre convention."""
    hw: tuple[int, int]
    """Image (height, width) these intrinsics describe."""
    dist: np.ndarray
    """float64 (n,) distortion coefficients in OpenCV's order (empty: none)."""
    fisheye: bool
    """True: ``dist`` is ``cv2.fisheye``'s (k1, k2, k3, k4); False: ``cv2.undistort``'s radial-tangential."""

    @property
    def distorted(self) -> bool:
        """Whether any distortion coefficient is non-zero."""
        return bool(np.any(self.dist != 0))


def pinhole(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """sray's K (3, 3) from a capture's focal lengths and principal point (its pixel (u, v) centred at +0.5)."""
    return np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])


def colmap_camera(model: str, params: np.ndarray, hw: tuple[int, int], what: str) -> CaptureCamera:
    """A COLMAP camera (model name, parameters, (H, W)) as a :class:`CaptureCamera`; ``what`` names it in errors."""
    p = [float(x) for x in params]
    counts = {name: n for name, n in COLMAP_MODELS.values()}
    if model not in counts:
        raise ValueError(f"{what}: unknown camera model {model!r}; known: {', '.join(counts)}")
    if len(p) != counts[model]:
        raise ValueError(f"{what}: model {model} takes {counts[model]} parameters, got {len(p)}")
    if model not in _COLMAP_OPENCV:
        raise ValueError(f"{what}: camera model {model} cannot be undistorted with OpenCV; re-run COLMAP's "
                         "image_undistorter (or calibrate with OPENCV / OPENCV_FISHEYE) and convert its output")
    intrinsics, dist, fisheye = _COLMAP_OPENCV[model](p)
    return CaptureCamera(pinhole(*intrinsics), hw, np.array(dist, dtype=np.float64), fisheye)


def nerfstudio_camera(fields: dict, what: str) -> CaptureCamera:
    """A camera from nerfstudio's transforms.json fields (frame over top level); ``what`` names it."""
    model = str(fields.get("camera_model", "OPENCV")).upper()
    missing = [k for k in ("fl_x", "cx", "cy", "w", "h") if k not in fields]
    if missing:
        raise ValueError(f"{what}: fields {missing} are missing (nerfstudio stores them at the top level or per frame)")
    fx = float(fields["fl_x"])
    fy = float(fields.get("fl_y", fx))
    hw = (int(fields["h"]), int(fields["w"]))
    K = pinhole(fx, fy, float(fields["cx"]), float(fields["cy"]))
    k = [float(fields.get(f"k{i}", 0.0)) for i in (1, 2, 3, 4)]
    p = [float(fields.get(f"p{i}", 0.0)) for i in (1, 2)]
    if model in ("PINHOLE", "SIMPLE_PINHOLE", "PERSPECTIVE"):
        if any(k) or any(p):
            raise ValueError(f"{what}: camera_model {model} with distortion terms k={k} p={p}; set camera_model OPENCV")
        return CaptureCamera(K, hw, np.zeros(0), False)
    if model == "OPENCV":
        if k[3] != 0.0:
            raise ValueError(f"{what}: camera_model OPENCV has no k4 (got {k[3]}); is it OPENCV_FISHEYE?")
        return CaptureCamera(K, hw, np.array([k[0], k[1], p[0], p[1], k[2]]), False)
    if model == "OPENCV_FISHEYE":
        if any(p):
            raise ValueError(f"{what}: camera_model OPENCV_FISHEYE has no tangential terms (got p={p})")
        return CaptureCamera(K, hw, np.array(k), True)
    raise ValueError(f"{what}: camera_model {model} cannot be undistorted with OpenCV; give OPENCV, "
                     "OPENCV_FISHEYE or PINHOLE frames")


def undistort_maps(camera: CaptureCamera) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y) float32 (H, W) for ``cv2.remap``: the source pixel of each pixel of the undistorted image,
    which keeps ``camera.K`` (OpenCV centres pixels as sray does); borders the lens never saw stay black."""
    h, w = camera.hw
    if camera.fisheye:
        return cv2.fisheye.initUndistortRectifyMap(camera.K, camera.dist, np.eye(3), camera.K, (w, h), cv2.CV_32FC1)
    return cv2.initUndistortRectifyMap(camera.K, camera.dist, None, camera.K, (w, h), cv2.CV_32FC1)


def undistort(image: np.ndarray, camera: CaptureCamera, nearest: bool = False) -> np.ndarray:
    """``image`` (H, W[, C]) as ``camera.K`` sees it: bilinear, or ``nearest`` for depth; 0 outside the source."""
    if not camera.distorted:
        return image
    if image.shape[:2] != camera.hw:
        raise ValueError(f"image is {image.shape[1]}x{image.shape[0]}, its camera {camera.hw[1]}x{camera.hw[0]}")
    map_x, map_y = undistort_maps(camera)
    mode = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.remap(image, map_x, map_y, mode, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
