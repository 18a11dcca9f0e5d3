"""Reader: a nerfstudio capture (``ns-process-data``'s ``transforms.json``, images, optional depth maps and
``ply_file_path`` points), without labels; ``c2w_opencv = transform_matrix @ diag(1, -1, -1, 1)`` (OpenGL axes),
``applied_transform`` only recorded; frames in ``file_path`` order. Conventions: docs/capture.md."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sray.data_tools.readers.camera_models import nerfstudio_camera
from sray.data_tools.readers.capture import CaptureFrame, capture_scene
from sray.data_tools.readers.common import read_file
from sray.data_tools.readers.point_cloud import read_ply_points
from sray.data_tools.scene import Scene

OPENGL_TO_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])
"""Right-multiplied on an OpenGL camera-to-world: flips the camera's y and z axes."""
CAMERA_FIELDS = ("camera_model", "fl_x", "fl_y", "cx", "cy", "w", "h", "k1", "k2", "k3", "k4", "p1", "p2")


def read_transforms(path: Path) -> dict:
    """The parsed transforms.json; errors name the file."""
    text = read_file(path, "missing; is this a nerfstudio capture (ns-process-data output)?", text=True)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list) or not data["frames"]:
        raise ValueError(f"{path}: field 'frames' must be a non-empty list")
    return data


def frame_c2w(frame: dict, where: str) -> np.ndarray:
    """OpenCV camera-to-world (4, 4) of a frame's ``transform_matrix`` (4x4, or its top 3x4)."""
    try:
        m = np.asarray(frame["transform_matrix"], dtype=np.float64)
    except KeyError:
        raise ValueError(f"{where}: field 'transform_matrix' is missing") from None
    except (TypeError, ValueError):
        raise ValueError(f"{where}: field 'transform_matrix' is not a numeric matrix") from None
    if m.shape == (3, 4):
        m = np.vstack([m, [0.0, 0.0, 0.0, 1.0]])
    if m.shape != (4, 4):
        raise ValueError(f"{where}: field 'transform_matrix' has shape {m.shape}, expected 4x4")
    return m @ OPENGL_TO_OPENCV


def read_nerfstudio(src: Path, name: str, label_space: str = "scannet20", size_hw: tuple[int, int] | None = (240, 320),
                    frame_skip: int = 1, depth_scale: float = 1000.0, scale: float | None = None) -> Scene:
    """Open a nerfstudio capture as an unlabelled scene (views load lazily); ``scale``: ``--scale``."""
    src = Path(src)
    path = src if src.suffix == ".json" else src / "transforms.json"
    root = path.parent
    data = read_transforms(path)
    top = {k: data[k] for k in CAMERA_FIELDS if k in data}
    entries = []
    for index, frame in enumerate(data["frames"]):
        where = f"{path}: frames[{index}]"
        if not isinstance(frame, dict) or not isinstance(frame.get("file_path"), str):
            raise ValueError(f"{where}: field 'file_path' is missing")
        camera = nerfstudio_camera({**top, **{k: frame[k] for k in CAMERA_FIELDS if k in frame}},
                                   f"{where} ({frame['file_path']})")
        image = root / frame["file_path"]
        if not image.is_file():
            raise FileNotFoundError(f"{image}: missing (named by {where}.file_path)")
        depth = root / frame["depth_file_path"] if isinstance(frame.get("depth_file_path"), str) else None
        if depth is not None and not depth.is_file():
            raise FileNotFoundError(f"{depth}: missing (named by {where}.depth_file_path)")
        entries.append((frame["file_path"], CaptureFrame(image=image, camera=camera, c2w=frame_c2w(frame, where),
                                                         depth=depth)))
    some_depth = [f for _, f in entries if f.depth is not None]
    if some_depth and len(some_depth) != len(entries):
        raise ValueError(f"{path}: {len(some_depth)} of {len(entries)} frames have a depth_file_path; give every "
                         "frame one, or none")
    ply = data.get("ply_file_path")
    points = read_ply_points(root / ply) if isinstance(ply, str) else np.zeros((0, 3))
    frames = [f for _, f in sorted(entries, key=lambda e: e[0])]
    extra = {"transforms": str(path)}
    if "applied_transform" in data:
        extra["applied_transform"] = data["applied_transform"]
    return capture_scene(frames, points, src=src, name=name, source_format="nerfstudio", label_space=label_space,
                         size_hw=size_hw, frame_skip=frame_skip, depth_scale=depth_scale, scale=scale, extra=extra)
