"""COLMAP sparse models (``cameras``, ``images``, ``points3D``) in text (``.txt``) or binary (``.bin``) form.

Binary layout (little-endian): ``cameras.bin`` = uint64 count, then per camera int32 id, int32 model id,
uint64 width, uint64 height, float64 params[n(model)]. ``images.bin`` = uint64 count, then per image int32
id, float64 qw qx qy qz, float64 tx ty tz, int32 camera id, a NUL-terminated name, uint64 n2D, then n2D x
(float64 x, float64 y, int64 point3D id; -1 = none). ``points3D.bin`` = uint64 count, then per point uint64
id, float64 x y z, uint8 r g b, float64 error, uint64 track length, then length x (int32 image id, int32
point2D index). The text files hold the same fields, one camera / point per line and two lines per image,
``#`` starting a comment.

A pose (q, t) maps world to camera: x_cam = R(q) x_world + t, with COLMAP's camera axes x right, y down, z
forward (OpenCV's, so sray needs no axis change): c2w = [[R^T, -R^T t], [0, 0, 0, 1]].
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sray.data_tools.readers.camera_models import COLMAP_MODELS


@dataclass(frozen=True)
class ColmapCamera:
    """One camera of ``cameras``: model name, image size and parameters."""

    camera_id: int
    model: str
    width: int
    height: int
    params: np.ndarray
    """float64 (n,) in the model's order."""


@dataclass(frozen=True)
class ColmapImage:
    """One registered image of ``images``: its world-to-camera pose, camera, file name and observed points."""

    image_id: int
    qvec: np.ndarray
    """float64 (4,) rotation quaternion (w, x, y, z), world to camera."""
    tvec: np.ndarray
    """float64 (3,) translation, world to camera."""
    camera_id: int
    name: str
    """Image file name relative to the image folder."""
    point3d_ids: np.ndarray
    """int64 (n,) ids of the 3D points its keypoints observe (-1 entries removed)."""


@dataclass(frozen=True)
class ColmapModel:
    """A whole sparse model."""

    cameras: dict[int, ColmapCamera]
    images: dict[int, ColmapImage]
    points: dict[int, np.ndarray]
    """Point id -> float64 (3,) world position."""
    folder: Path
    """Where it was read from (error messages)."""


def qvec_to_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def image_c2w(image: ColmapImage, where: str) -> np.ndarray:
    """Camera-to-world (4, 4), OpenCV axes, of an image; ValueError when its quaternion is not unit length."""
    norm = float(np.linalg.norm(image.qvec))
    if not np.isfinite(norm) or abs(norm - 1.0) > 1e-3:
        raise ValueError(f"{where}: image {image.image_id} ({image.name}) has quaternion {image.qvec.tolist()} of "
                         f"length {norm:.4g}, not 1; the model is damaged")
    R = qvec_to_rotation(image.qvec / norm)
    c2w = np.eye(4)
    c2w[:3, :3] = R.T
    c2w[:3, 3] = -R.T @ image.tvec
    return c2w


class _Bytes:
    """A little-endian cursor over one binary file; errors name the file."""

    def __init__(self, path: Path) -> None:
        self.path, self.data, self.at = path, path.read_bytes(), 0

    def read(self, fmt: str) -> tuple:
        size = struct.calcsize("<" + fmt)
        if self.at + size > len(self.data):
            raise ValueError(f"{self.path}: ends after {len(self.data)} bytes in the middle of a record (truncated?)")
        values = struct.unpack_from("<" + fmt, self.data, self.at)
        self.at += size
        return values

    def name(self) -> str:
        end = self.data.find(b"\0", self.at)
        if end < 0:
            raise ValueError(f"{self.path}: an image name has no terminating NUL byte (truncated?)")
        text, self.at = self.data[self.at:end].decode("utf-8"), end + 1
        return text


def _read_bin(folder: Path) -> tuple[dict, dict, dict]:
    """cameras, images, points of ``folder/{cameras,images,points3D}.bin``."""
    cameras, images, points = {}, {}, {}
    f = _Bytes(folder / "cameras.bin")
    for _ in range(f.read("Q")[0]):
        cam_id, model_id, width, height = f.read("iiQQ")
        if model_id not in COLMAP_MODELS:
            raise ValueError(f"{f.path}: camera {cam_id} has unknown model id {model_id}")
        name, n = COLMAP_MODELS[model_id]
        cameras[cam_id] = ColmapCamera(cam_id, name, int(width), int(height), np.array(f.read("d" * n)))
    f = _Bytes(folder / "images.bin")
    for _ in range(f.read("Q")[0]):
        image_id, *pose, cam_id = f.read("i7di")
        name = f.name()
        n2d = f.read("Q")[0]
        obs = np.array(f.read("ddq" * n2d), dtype=np.float64).reshape(n2d, 3) if n2d else np.zeros((0, 3))
        ids = obs[:, 2].astype(np.int64)
        images[image_id] = ColmapImage(image_id, np.array(pose[:4]), np.array(pose[4:]), cam_id, name, ids[ids >= 0])
    f = _Bytes(folder / "points3D.bin")
    for _ in range(f.read("Q")[0]):
        point_id, x, y, z, _r, _g, _b, _err = f.read("QdddBBBd")
        f.read("ii" * f.read("Q")[0])
        points[int(point_id)] = np.array([x, y, z])
    return cameras, images, points


def _data_lines(path: Path) -> list[str]:
    """Lines of a text model file without comments (blank lines kept: an image's point line may be empty)."""
    try:
        return [line.strip() for line in path.read_text().splitlines() if not line.lstrip().startswith("#")]
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing; a COLMAP text model has cameras.txt, images.txt, "
                                "points3D.txt") from None


def _read_txt(folder: Path) -> tuple[dict, dict, dict]:
    """cameras, images, points of ``folder/{cameras,images,points3D}.txt``."""
    cameras, images, points = {}, {}, {}
    path = folder / "cameras.txt"
    for line in filter(None, _data_lines(path)):
        parts = line.split()
        try:
            cameras[int(parts[0])] = ColmapCamera(int(parts[0]), parts[1], int(parts[2]), int(parts[3]),
                                                  np.array([float(v) for v in parts[4:]]))
        except (IndexError, ValueError):
            raise ValueError(f"{path}: line {line!r} is not CAMERA_ID MODEL WIDTH HEIGHT PARAMS...") from None
    path = folder / "images.txt"
    lines = _data_lines(path)
    i = 0
    while i < len(lines):
        if not lines[i]:
            i += 1
            continue
        parts, obs = lines[i].split(), (lines[i + 1].split() if i + 1 < len(lines) else [])
        try:
            ids = np.array([int(v) for v in obs[2::3]], dtype=np.int64)
            images[int(parts[0])] = ColmapImage(int(parts[0]), np.array([float(v) for v in parts[1:5]]),
                                                np.array([float(v) for v in parts[5:8]]), int(parts[8]),
                                                " ".join(parts[9:]), ids[ids >= 0])
        except (IndexError, ValueError):
            raise ValueError(f"{path}: line {lines[i]!r} is not IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME "
                             "(followed by a line of X Y POINT3D_ID triples)") from None
        i += 2
    path = folder / "points3D.txt"
    for line in filter(None, _data_lines(path)):
        parts = line.split()
        try:
            points[int(parts[0])] = np.array([float(v) for v in parts[1:4]])
        except (IndexError, ValueError):
            raise ValueError(f"{path}: line {line!r} is not POINT3D_ID X Y Z R G B ERROR TRACK...") from None
    return cameras, images, points


def find_model(src: Path) -> Path:
    """The sparse model folder of a capture: ``src`` itself, ``src/sparse/0`` or ``src/sparse`` (first holding
    ``cameras.bin`` or ``cameras.txt``); FileNotFoundError naming the places otherwise."""
    for folder in (src, src / "sparse" / "0", src / "sparse", src / "colmap" / "sparse" / "0"):
        if (folder / "cameras.bin").is_file() or (folder / "cameras.txt").is_file():
            return folder
    raise FileNotFoundError(f"{src}: no COLMAP model (looked for cameras.bin / cameras.txt in {src}, {src}/sparse/0, "
                            f"{src}/sparse, {src}/colmap/sparse/0); pass --sparse MODEL_FOLDER")


def read_model(folder: Path) -> ColmapModel:
    """Read a COLMAP model folder, binary when ``cameras.bin`` is there, else text; checks image cameras exist."""
    folder = Path(folder)
    try:
        cameras, images, points = _read_bin(folder) if (folder / "cameras.bin").is_file() else _read_txt(folder)
    except FileNotFoundError as e:
        raise FileNotFoundError(f"{e.filename or e}: missing; a COLMAP model holds cameras, images and "
                                "points3D") from None
    for image in images.values():
        if image.camera_id not in cameras:
            raise ValueError(f"{folder}: image {image.image_id} ({image.name}) uses camera {image.camera_id}, which "
                             "cameras does not list")
    if not images:
        raise ValueError(f"{folder}: the model registers no image")
    return ColmapModel(cameras, images, points, folder)
