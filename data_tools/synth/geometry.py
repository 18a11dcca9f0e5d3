"""Box primitives of the procedural scenes (world frame: metres, z up, floor at z = 0) and vectorised ray casting:
quarter-turned boxes are folded into axis-aligned ones, and with ``dirs = R K^-1 [u, v, 1]`` (not unit length) the
hit parameter ``t`` is the camera z-depth."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from sray.data_tools.synth.materials import Material


@dataclass(frozen=True)
class Box:
    """One oriented box (world or object frame): centre and full extents along its axes (m), class id (IGNORE_ID for
    props), material (in the box's frame), yaw about z (rad); light fixtures cast no shadow (on their own light)."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    label: int
    material: Material
    yaw: float = 0.0
    casts_shadow: bool = True


def place(boxes: list[Box], x: float, y: float, yaw: float, z: float = 0.0) -> list[Box]:
    """Move boxes built in an object frame to world position (x, y, z) turned by ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    return [replace(b, center=(x + c * b.center[0] - s * b.center[1], y + s * b.center[0] + c * b.center[1],
                               z + b.center[2]), yaw=b.yaw + yaw) for b in boxes]


def _canonical(yaw: float, size: tuple[float, float, float]) -> tuple[float, tuple[float, float, float], int]:
    """(yaw, size, quarter turns folded away): a yaw within 1e-9 of k*90 degrees becomes 0."""
    quarters = yaw / (math.pi / 2)
    k = round(quarters)
    if abs(quarters - k) < 1e-9:
        sx, sy, sz = size
        return 0.0, ((sy, sx, sz) if k % 2 else (sx, sy, sz)), k % 4
    return math.remainder(yaw, 2 * math.pi), size, 0


@dataclass
class PackedBoxes:
    """Structure-of-arrays form of P boxes for the ray caster: ``center`` float64 (P, 3); ``half`` float64 (P, 3)
    half extents after folding quarter turns; ``yaw`` float64 (P,) residual yaw; ``quarter`` int64 (P,) quarter
    turns folded into ``half`` (keeps textures on the object); ``label`` int64 (P,); ``casts_shadow`` bool (P,)."""

    center: np.ndarray
    half: np.ndarray
    yaw: np.ndarray
    quarter: np.ndarray
    label: np.ndarray
    casts_shadow: np.ndarray
    materials: list[Material]

    @classmethod
    def from_boxes(cls, boxes: list[Box]) -> PackedBoxes:
        """Pack a list of boxes (validates positive extents)."""
        if not boxes:
            raise ValueError("a scene needs at least one box")
        yaws, halves, quarters = [], [], []
        for b in boxes:
            if min(b.size) <= 0:
                raise ValueError(f"box with label {b.label} has non-positive size {b.size}")
            yaw, size, k = _canonical(b.yaw, b.size)
            yaws.append(yaw)
            halves.append([0.5 * v for v in size])
            quarters.append(k)
        return cls(center=np.array([b.center for b in boxes], np.float64),
                   half=np.array(halves, np.float64), yaw=np.array(yaws, np.float64),
                   quarter=np.array(quarters, np.int64), label=np.array([b.label for b in boxes], np.int64),
                   casts_shadow=np.array([b.casts_shadow for b in boxes], bool),
                   materials=[b.material for b in boxes])

    def __len__(self) -> int:
        """Number of boxes P."""
        return len(self.materials)

    def to_local(self, index: np.ndarray, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) -> the frames of boxes ``index`` (N,), relative to their centres."""
        return in_frame(points - self.center[index], np.cos(self.yaw[index]), np.sin(self.yaw[index]))

    def overlaps(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """bool (P,): the box's world-axis bounding box meets the region [lo, hi] (each (3,))."""
        c, s = np.abs(np.cos(self.yaw)), np.abs(np.sin(self.yaw))
        ext = np.stack([c * self.half[:, 0] + s * self.half[:, 1], s * self.half[:, 0] + c * self.half[:, 1],
                        self.half[:, 2]], axis=1)
        return np.all((self.center + ext >= lo) & (self.center - ext <= hi), axis=1)

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """bool (N, P): point n lies inside box p grown by ``margin`` on every side."""
        local = in_frame(points[:, None, :] - self.center[None, :, :], np.cos(self.yaw)[None, :],
                         np.sin(self.yaw)[None, :])
        return np.all(np.abs(local) <= self.half[None, :, :] + margin, axis=2)


def in_frame(v: np.ndarray, c: np.ndarray | float, s: np.ndarray | float) -> np.ndarray:
    """Vectors (..., 3) in a frame turned about z by the angle of cosine ``c``, sine ``s`` (broadcast as v[..., 0])."""
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1], v[..., 2]], -1)


def _safe_inverse(d: np.ndarray) -> np.ndarray:
    """1 / d with exact zeros nudged to a tiny signed value (float32 (N, 3))."""
    d = np.where(np.abs(d) < 1e-12, 1e-12, d)
    return (1.0 / d).astype(np.float32)


def cast_rays(origin: np.ndarray, dirs: np.ndarray, boxes: PackedBoxes, active: np.ndarray | None = None,
              t_min: float = 1e-4, chunk: int = 8192) -> tuple[np.ndarray, np.ndarray]:
    """Nearest box hit of rays from one origin (3,) along ``dirs`` (N, 3), any length: (t float32 (N,), box int64 (N,));
    ``active`` bool (P,) boxes to test; hits at t <= t_min ignored, misses t = inf, index -1."""
    n = len(dirs)
    best_t = np.full(n, np.inf, np.float32)
    best_i = np.full(n, -1, np.int64)
    chosen = np.arange(len(boxes)) if active is None else np.flatnonzero(active)
    if chosen.size == 0:
        return best_t, best_i
    groups: dict[float, list[int]] = {}
    for p in chosen:
        groups.setdefault(float(boxes.yaw[p]), []).append(int(p))
    for yaw, members in groups.items():
        idx = np.array(members)
        c, s = math.cos(yaw), math.sin(yaw)
        inv = _safe_inverse(in_frame(dirs, c, s))
        o_local = in_frame(origin[None, :] - boxes.center[idx], c, s)
        lo = (-boxes.half[idx] - o_local).astype(np.float32)
        hi = (boxes.half[idx] - o_local).astype(np.float32)
        for start in range(0, n, chunk):
            sl = slice(start, start + chunk)
            t_near, t_far = None, None
            for k in range(3):
                a = inv[sl, k:k + 1] * lo[None, :, k]
                b = inv[sl, k:k + 1] * hi[None, :, k]
                near_k, far_k = np.minimum(a, b), np.maximum(a, b)
                t_near = near_k if t_near is None else np.maximum(t_near, near_k, out=t_near)
                t_far = far_k if t_far is None else np.minimum(t_far, far_k, out=t_far)
            miss = (t_near > t_far) | (t_near <= t_min)
            t_near[miss] = np.inf
            j = np.argmin(t_near, axis=1)
            t = t_near[np.arange(len(j)), j]
            better = t < best_t[sl]
            best_t[sl] = np.where(better, t, best_t[sl])
            best_i[sl] = np.where(better, idx[j], best_i[sl])
    return best_t, best_i


def cast_shell(origin: np.ndarray, dirs: np.ndarray, room: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Exit of rays from inside the room's interior box: (t float32 (N,), face int64 (N,)); faces 0 = x=0 wall,
    1 = x=Lx wall, 2 = y=0 wall, 3 = y=Ly wall, 4 = floor, 5 = ceiling."""
    hi = np.asarray(room, np.float64)
    inv = _safe_inverse(dirs)
    pos = inv > 0
    bound = np.where(pos, hi[None, :], 0.0)
    t_axes = ((bound - origin[None, :]) * inv).astype(np.float32)
    axis = np.argmin(t_axes, axis=1)
    t = t_axes[np.arange(len(dirs)), axis]
    face = 2 * axis + pos[np.arange(len(dirs)), axis]
    return t, face


def box_normals(boxes: PackedBoxes, index: np.ndarray, local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward normals at local hit points: (world normals float32 (N, 3), local face axis int64 (N,))."""
    ratio = np.abs(local) / boxes.half[index]
    axis = np.argmax(ratio, axis=1)
    sign = np.sign(local[np.arange(len(local)), axis])
    n_local = np.zeros_like(local)
    n_local[np.arange(len(local)), axis] = sign
    world = in_frame(n_local, np.cos(boxes.yaw[index]), -np.sin(boxes.yaw[index]))
    return world.astype(np.float32), axis
