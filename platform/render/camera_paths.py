"""Built fly-through paths (docs/render.md, "Camera paths"): a spline through a scene's cameras or an orbit
around them. Poses are float64 (4, 4) camera-to-world in OpenCV axes (x right, y down, z forward)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.platform.render.rotations import matrix_to_quaternion, quaternion_to_matrix, rotation_angle, slerp

TURN_METRES_PER_RADIAN = 0.5
"""A turn of one radian takes as long as moving half a metre (a camera turning in place still moves on)."""
SAME_POSE = 1e-9  # consecutive key cameras closer than this (metres + weighted radians) count as one


@dataclass(frozen=True)
class CameraPath:
    """One camera per frame: ``c2w`` float64 (N, 4, 4) camera-to-world (OpenCV axes), ``K`` float64 (N, 3, 3) at
    ``hw`` = (H, W), pixel (u, v) centred at (u, v); ``describe``: the path's origin (``spline through 16 cameras``)."""

    c2w: np.ndarray
    K: np.ndarray
    hw: tuple[int, int]
    describe: str

    def __len__(self) -> int:
        """Number of frames."""
        return int(self.c2w.shape[0])


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(4, 4) camera-to-world (OpenCV axes) at ``eye`` (3,) looking at ``target`` (3,), image up along ``up`` (3,)."""
    z = np.asarray(target, np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    c2w[:3, 3] = eye
    return c2w


def key_times(c2ws: np.ndarray) -> np.ndarray:
    """Time (K,) of each key camera (K, 4, 4): cumulative metres moved plus weighted radians turned."""
    steps = [np.linalg.norm(c2ws[i + 1, :3, 3] - c2ws[i, :3, 3])
             + TURN_METRES_PER_RADIAN * rotation_angle(c2ws[i, :3, :3], c2ws[i + 1, :3, :3])
             for i in range(len(c2ws) - 1)]
    return np.concatenate([[0.0], np.cumsum(steps)])


def _tangents(points: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Catmull-Rom velocities (K, 3) at keys ``points`` (K, 3) reached at ``times`` (K,): the time-weighted
    mean of the two neighbouring chord slopes inside, the one chord slope at each end."""
    slopes = np.diff(points, axis=0) / np.diff(times)[:, None]                         # (K-1, 3)
    out = np.empty_like(points)
    out[0], out[-1] = slopes[0], slopes[-1]
    before, after = np.diff(times)[:-1, None], np.diff(times)[1:, None]                # (K-2, 1) each
    out[1:-1] = (after * slopes[:-1] + before * slopes[1:]) / (before + after)
    return out


def spline_path(c2ws: np.ndarray, n_frames: int) -> np.ndarray:
    """``n_frames`` poses (n_frames, 4, 4) through the key cameras ``c2ws`` (K, 4, 4) in their order: a Hermite
    spline with Catmull-Rom tangents for positions, SLERP for rotations, each key reached at its
    :func:`key_times` and frames evenly spread in that time. Consecutive duplicates count once."""
    if n_frames < 1 or len(c2ws) < 1:
        raise ValueError(f"a spline path needs >= 1 frame and >= 1 key camera (got {n_frames} and {len(c2ws)})")
    keys = [np.asarray(c2ws[0], np.float64)]
    for pose in c2ws[1:]:
        if key_times(np.stack([keys[-1], pose]))[1] > SAME_POSE:
            keys.append(np.asarray(pose, np.float64))
    if len(keys) == 1:
        return np.repeat(keys[0][None], n_frames, axis=0)
    keys_arr = np.stack(keys)
    times = key_times(keys_arr)
    points, quats = keys_arr[:, :3, 3], [matrix_to_quaternion(k[:3, :3]) for k in keys_arr]
    velocity = _tangents(points, times)
    frame_t = np.linspace(0.0, times[-1], n_frames)
    segment = np.clip(np.searchsorted(times, frame_t, side="right") - 1, 0, len(times) - 2)
    out = np.repeat(np.eye(4)[None], n_frames, axis=0)
    for i in np.unique(segment):
        idx = np.nonzero(segment == i)[0]
        duration = times[i + 1] - times[i]
        s = (frame_t[idx] - times[i]) / duration
        h = s[:, None]                                                                 # cubic Hermite basis
        out[idx, :3, 3] = ((2 * h**3 - 3 * h**2 + 1) * points[i] + (h**3 - 2 * h**2 + h) * duration * velocity[i]
                           + (-2 * h**3 + 3 * h**2) * points[i + 1] + (h**3 - h**2) * duration * velocity[i + 1])
        out[idx, :3, :3] = np.stack([quaternion_to_matrix(q) for q in slerp(quats[i], quats[i + 1], s)])
    out[-1], out[0] = keys_arr[-1], keys_arr[0]                                        # exact ends, no round trip
    return out


def orbit_path(c2ws: np.ndarray, n_frames: int) -> np.ndarray:
    """``n_frames`` poses (n_frames, 4, 4) on one circle around the cameras ``c2ws`` (K, 4, 4): centred on their
    mean position, at their mean height and mean distance from the vertical through it (up: their mean up),
    looking at the centre, starting on the first camera's side, counter-clockwise seen from above."""
    centres = c2ws[:, :3, 3]
    centre = centres.mean(axis=0)
    up = -c2ws[:, :3, 1].mean(axis=0)                                                  # OpenCV y points down
    if np.linalg.norm(up) < 1e-6:
        raise ValueError("the cameras' up directions cancel out: no orbit plane; use the spline path")
    up /= np.linalg.norm(up)
    flat = (centres - centre) - np.outer((centres - centre) @ up, up)                  # (K, 3) in the orbit plane
    radius = float(np.linalg.norm(flat, axis=1).mean())
    if radius < 1e-3:
        raise ValueError("the cameras stand on one vertical line: an orbit around them has no radius; use the "
                         "spline path")
    start = flat[int(np.argmax(np.linalg.norm(flat, axis=1) > 1e-3))]
    e1 = start / np.linalg.norm(start)
    e2 = np.cross(up, e1)
    angles = 2 * np.pi * np.arange(n_frames) / n_frames
    eyes = centre + radius * (np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2)
    return np.stack([look_at(eye, centre, up) for eye in eyes])
