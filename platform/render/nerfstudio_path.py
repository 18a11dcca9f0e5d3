"""nerfstudio's ``camera_path.json``, read and checked (docs/render.md): ``camera_to_world`` in OpenGL camera axes,
flipped to OpenCV's; ``fov`` vertical, in degrees. A problem is refused in one line naming the file and field."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from sray.platform.render.camera_paths import CameraPath
from sray.platform.render.rotations import rigid_problem

OPENGL_TO_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])
"""Right-multiplied onto an OpenGL camera-to-world: flips the camera's y and z axes."""
LAYOUT_HINT = "see docs/render.md for the camera_path.json layout"


def fov_intrinsics(fov_deg: float, hw: tuple[int, int]) -> np.ndarray:
    """(3, 3) K of vertical FOV ``fov_deg`` at ``hw`` = (H, W): f = (H/2)/tan(fov/2), centre ((W-1)/2, (H-1)/2)."""
    h, w = hw
    f = (h / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def _number(value: Any) -> bool:
    """True for an int or float that is not a bool."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _field(d: dict[str, Any], key: str, where: str, path: Path, valid: Callable[[Any], bool], must: str) -> Any:
    """``d[key]``; ValueError naming ``path`` and the field ``where`` when it is missing or not ``valid``."""
    if key not in d:
        raise ValueError(f"{path}: field '{where}' is missing; {LAYOUT_HINT}")
    if not valid(d[key]):
        raise ValueError(f"{path}: field '{where}' is {str(d[key])[:60]}; it must be {must}")
    return d[key]


def _pixels(doc: dict[str, Any], key: str, path: Path) -> int:
    """A required positive whole number of pixels of the top level."""
    return int(_field(doc, key, key, path, lambda v: _number(v) and v == int(v) and v >= 1,
                      "a positive whole number of pixels"))


def _frame_pose(frame: Any, i: int, path: Path) -> tuple[np.ndarray, float]:
    """OpenCV c2w (4, 4) and fov in degrees of ``camera_path[i]``; ValueError names the field."""
    where = f"camera_path[{i}]"
    if not isinstance(frame, dict):
        raise ValueError(f"{path}: field '{where}' is {type(frame).__name__}, not an object; {LAYOUT_HINT}")
    flat = _field(frame, "camera_to_world", f"{where}.camera_to_world", path,
                  lambda v: isinstance(v, list) and len(v) == 16 and all(_number(x) for x in v),
                  "16 numbers (a 4x4 matrix row by row)")
    c2w_gl = np.asarray(flat, np.float64).reshape(4, 4)
    problem = rigid_problem(c2w_gl)
    if problem is not None:
        raise ValueError(f"{path}: field '{where}.camera_to_world' is not a rigid pose: {problem}; write a rotation "
                         "and a translation only")
    fov = _field(frame, "fov", f"{where}.fov", path, lambda v: _number(v) and 0.0 < v < 180.0,
                 "a vertical field of view in degrees, between 0 and 180")
    return c2w_gl @ OPENGL_TO_OPENCV, float(fov)


def read_camera_path(path: Path, size_hw: tuple[int, int] | None = None) -> tuple[CameraPath, float | None]:
    """The cameras of a nerfstudio ``camera_path.json`` and its ``fps`` (None when absent); ``size_hw``: (H, W)
    to render at instead of the file's size (the focal length follows the height rendered)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such camera-path file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a readable JSON file ({e}); {LAYOUT_HINT}") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: the top level is {type(doc).__name__}, not an object; {LAYOUT_HINT}")
    kind = doc.get("camera_type", "perspective")
    if kind != "perspective":
        raise ValueError(f"{path}: field 'camera_type' is {kind!r}; only 'perspective' cameras can be rendered")
    file_hw = (_pixels(doc, "render_height", path), _pixels(doc, "render_width", path))
    frames = _field(doc, "camera_path", "camera_path", path, lambda v: isinstance(v, list) and bool(v),
                    f"a non-empty list of frames; {LAYOUT_HINT}")
    fps = doc.get("fps")
    if fps is not None and (not _number(fps) or fps <= 0):
        raise ValueError(f"{path}: field 'fps' is {fps!r}; it must be a positive number of frames per second")
    hw = size_hw or file_hw
    poses, fovs = zip(*(_frame_pose(frame, i, path) for i, frame in enumerate(frames)))
    cameras = CameraPath(c2w=np.stack(poses), K=np.stack([fov_intrinsics(fov, hw) for fov in fovs]), hw=hw,
                         describe=f"camera-path file {path.name}")
    return cameras, None if fps is None else float(fps)
