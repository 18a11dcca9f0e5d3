"""Geometry and file helpers shared by the dataset readers. Pixel (u, v) is centred at (u, v) in K's coordinates and
covers [u - 0.5, u + 0.5), so resizing by ``s`` along an axis maps ``u' + 0.5 = s * (u + 0.5)``."""

from __future__ import annotations

import re
from collections.abc import Callable, Container, Iterable
from pathlib import Path

import cv2
import numpy as np

from sray.data_tools.label_spaces import NYU40, SCANNET20_NYU40_IDS
from sray.data_tools.png import decode_png


def numbered_files(folder: Path, pattern: str, suffixes: tuple[str, ...]) -> dict[int, Path]:
    """Files of ``folder`` whose stem matches ``pattern`` (a regex with one group of digits, e.g. ``r"rgb_(\\d+)"``)
    and whose suffix is in ``suffixes``, by their number in numeric order; ValueError when two carry one number."""
    found: dict[int, Path] = {}
    regex = re.compile(rf"^{pattern}$")
    for path in sorted(folder.iterdir()):
        match = regex.match(path.stem)
        if path.suffix.lower() not in suffixes or match is None:
            continue
        index = int(match.group(1))
        if index in found:
            raise ValueError(f"{path}: frame {index} also stored as {found[index].name}; keep one of them")
        found[index] = path
    return dict(sorted(found.items()))


def read_file(path: Path, missing: str = "missing", text: bool = False) -> bytes | str:
    """The bytes (``text``: the text) of ``path``; FileNotFoundError "<path>: <missing>" when it is absent."""
    try:
        return path.read_text() if text else path.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: {missing}") from None


def read_image(path: Path) -> np.ndarray:
    """Decode a PNG or JPEG without loss of bit depth (16-bit stays 16-bit; colour comes back RGB)."""
    data = read_file(path)
    try:
        return decode_png(data, str(path))
    except ValueError:
        raise ValueError(f"{path}: not a readable image (corrupt or truncated file?)") from None


def read_rgb8(path: Path) -> np.ndarray:
    """An 8-bit RGB image (H, W, 3); ValueError naming the file otherwise."""
    rgb = read_image(path)
    if rgb.dtype != np.uint8 or rgb.ndim != 3:
        raise ValueError(f"{path}: colour must be 8-bit RGB, got {rgb.dtype} {rgb.shape}")
    return rgb


def kept_view_ids(poses: dict[int, np.ndarray], frame_skip: int, src: Path, dropped: dict[str, str]) -> dict[str, int]:
    """View id -> frame number of every ``frame_skip``-th usable frame; ValueError when none is left."""
    kept = list(poses)[::frame_skip]
    if not kept:
        raise ValueError(f"{src}: no usable frame (dropped: {dropped})")
    return {f"{frame:06d}": frame for frame in kept}


def select_frames(src: Path, frames: Iterable[int], companions: dict[str, Container[int]],
                  read_pose: Callable[[int], np.ndarray], bad_pose: Callable[[int], str], frame_skip: int
                  ) -> tuple[dict[int, np.ndarray], dict[str, int], dict[str, str]]:
    """(c2w (4, 4) by usable frame, view id -> frame of every ``frame_skip``-th, frame -> why it was dropped): a
    frame missing from a ``companions`` kind (depth, label, ...) or whose pose has -inf/NaN entries is dropped."""
    poses: dict[int, np.ndarray] = {}
    dropped: dict[str, str] = {}
    for frame in frames:
        missing = [kind for kind, files in companions.items() if frame not in files]
        if missing:
            dropped[str(frame)] = f"no {' or '.join(missing)} file"
        elif np.isfinite(c2w := read_pose(frame)).all():
            poses[frame] = c2w
        else:
            dropped[str(frame)] = bad_pose(frame)
    return poses, kept_view_ids(poses, frame_skip, src, dropped), dropped


def scale_intrinsics(K: np.ndarray, src_hw: tuple[int, int], dst_hw: tuple[int, int]) -> np.ndarray:
    """K (3, 3) for ``src_hw`` resampled to ``dst_hw``: with s = dst / src, f' = s f, c' = s (c + 0.5) - 0.5."""
    sy, sx = dst_hw[0] / src_hw[0], dst_hw[1] / src_hw[1]
    out = np.array(K, dtype=np.float64)
    out[0, :2] *= sx
    out[0, 2] = sx * (K[0, 2] + 0.5) - 0.5
    out[1, :2] *= sy
    out[1, 2] = sy * (K[1, 2] + 0.5) - 0.5
    return out


def resample_nearest(image: np.ndarray, K_src: np.ndarray, K_dst: np.ndarray,
                     dst_hw: tuple[int, int], fill: int | float) -> np.ndarray:
    """``image`` (H, W) seen through K_src, resampled into K_dst (same centre and orientation: the affine warp K_src
    K_dst^-1) of size ``dst_hw``: each pixel takes the source pixel whose square holds its centre, ``fill`` outside."""
    h, w = dst_hw
    warp = np.asarray(K_src, np.float64) @ np.linalg.inv(np.asarray(K_dst, np.float64))
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    x = warp[0, 0] * u + warp[0, 1] * v + warp[0, 2]  # (h, w) source column coordinate
    y = warp[1, 0] * u + warp[1, 1] * v + warp[1, 2]  # (h, w) source row coordinate
    # Ties (a centre exactly on a pixel border, e.g. every pixel of a 2x downscale) go to the
    # right/lower pixel; the epsilon keeps float noise from deciding them.
    col, row = np.floor(x + 0.5 + 1e-6).astype(np.int64), np.floor(y + 0.5 + 1e-6).astype(np.int64)
    inside = (col >= 0) & (col < image.shape[1]) & (row >= 0) & (row < image.shape[0])
    out = np.full((h, w), fill, dtype=image.dtype)
    out[inside] = image[row[inside], col[inside]]
    return out


def resize_rgb(rgb: np.ndarray, dst_hw: tuple[int, int]) -> np.ndarray:
    """Area-averaged resize of a uint8 (H, W, 3) image (unchanged when already at ``dst_hw``)."""
    if rgb.shape[:2] == tuple(dst_hw):
        return rgb
    return cv2.resize(rgb, (dst_hw[1], dst_hw[0]), interpolation=cv2.INTER_AREA)


def read_depth_m(path: Path, depth_scale: float) -> np.ndarray:
    """16-bit depth PNG in ``depth_scale`` units per metre -> float32 (H, W) metres (0 = unknown)."""
    raw = read_image(path)
    if raw.dtype != np.uint16 or raw.ndim != 2:
        raise ValueError(f"{path}: depth must be a single-channel 16-bit PNG, got {raw.dtype} {raw.shape}")
    return raw.astype(np.float32) / np.float32(depth_scale)


def check_principal_point(K: np.ndarray, hw: tuple[int, int], what: str) -> None:
    """Raise ValueError when K's principal point lies outside an image of size ``hw``."""
    cx, cy = float(K[0, 2]), float(K[1, 2])
    if not (-0.5 <= cx <= hw[1] - 0.5 and -0.5 <= cy <= hw[0] - 0.5):
        raise ValueError(f"{what}: principal point ({cx:.1f}, {cy:.1f}) lies outside the {hw[1]}x{hw[0]} "
                         "images it is used with; are these intrinsics for another resolution?")


def nyu40_to_label(space: str) -> dict[int, int]:
    """NYU40 id (1..40) -> label id in ``space`` (``nyu40``: id - 1; ``scannet20``: benchmark index)."""
    if space == "nyu40":
        return {nyu: nyu - 1 for nyu in range(1, len(NYU40) + 1)}
    if space == "scannet20":
        return {nyu: index for index, nyu in enumerate(SCANNET20_NYU40_IDS)}
    raise ValueError(f"unknown label space {space!r}; the readers support 'scannet20' and 'nyu40'")
