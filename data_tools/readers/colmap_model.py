"""COLMAP sparse models (``cameras``, ``images``, ``points3D``) in text (``.txt``) or binary (``.bin``) form. Binary
(little-endian): ``cameras.bin`` = uint64 count, per camera int32 id, int32 model id, uint64 width, height, float64
params[n(model)]; ``images.bin`` = uint64 count, per image int32 id, float64 qw qx qy qz tx ty tz, int32 camera id, a
NUL-terminated name, uint64 n2D, n2D x (float64 x, y, int64 point3D id; -1 = none); ``points3D.bin`` = uint64 count, per
point uint64 id, float64 x y z, uint8 r g b, float64 error, uint64 track length, length x (int32 image id, int32 point2D
index). Text files hold the same fields, one camera / point per line, two lines per image, ``#`` comments. A pose (q, t)
maps world to camera, x_cam = R(q) x_world + t, in OpenCV's axes."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sray.data_tools.readers.camera_models import COLMAP_MODELS
from sray.data_tools.readers.common import read_file


@dataclass(frozen=True)
class ColmapCamera:
    """One camera of ``cameras``: model name, image size and float64 parameters in the model's order."""

    camera_id: int
    model: str
    width: int
    height: int
    params: np.ndarray


@dataclass(frozen=True)
class ColmapImage:
    """One registered image of ``images``: world-to-camera quaternion (w, x, y, z) and translation (float64), camera,
    file name (relative to the image folder) and int64 ids of the 3D points its keypoints observe."""

    image_id: int
    qvec: np.ndarray
    tvec: np.ndarray
    camera_id: int
    name: str
    point3d_ids: np.ndarray


@dataclass(frozen=True)
class ColmapModel:
    """A whole sparse model (points: id -> float64 (3,) world position)."""

    cameras: dict[int, ColmapCamera]
    images: dict[int, ColmapImage]
    points: dict[int, np.ndarray]


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
        """The next values of struct format ``fmt``; ValueError when the file ends first."""
        size = struct.calcsize("<" + fmt)
        if self.at + size > len(self.data):
            raise ValueError(f"{self.path}: ends after {len(self.data)} bytes in the middle of a record (truncated?)")
        values = struct.unpack_from("<" + fmt, self.data, self.at)
        self.at += size
        return values

    def name(self) -> str:
        """The next NUL-terminated UTF-8 string."""
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
    text = read_file(path, "missing; a COLMAP text model has cameras.txt, images.txt, points3D.txt", text=True)
    return [line.strip() for line in text.splitlines() if not line.lstrip().startswith("#")]


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
    lines = iter(_data_lines(path))
    for line in lines:
        if not line:
            continue
        parts, obs = line.split(), next(lines, "").split()  # an image's line, then its points' line
        try:
            ids = np.array([int(v) for v in obs[2::3]], dtype=np.int64)
            images[int(parts[0])] = ColmapImage(int(parts[0]), np.array([float(v) for v in parts[1:5]]),
                                                np.array([float(v) for v in parts[5:8]]), int(parts[8]),
                                                " ".join(parts[9:]), ids[ids >= 0])
        except (IndexError, ValueError):
            raise ValueError(f"{path}: line {line!r} is not IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME "
                             "(followed by a line of X Y POINT3D_ID triples)") from None
    path = folder / "points3D.txt"
    for line in filter(None, _data_lines(path)):
        parts = line.split()
        try:
            points[int(parts[0])] = np.array([float(v) for v in parts[1:4]])
        except (IndexError, ValueError):
            raise ValueError(f"{path}: line {line!r} is not POINT3D_ID X Y Z R G B ERROR TRACK...") from None
    return cameras, images, points


def find_model(src: Path) -> Path:
    """The sparse model folder of a capture (the first holding cameras.bin/.txt); FileNotFoundError else."""
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
    return ColmapModel(cameras, images, points)
