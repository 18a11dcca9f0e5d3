"""Box primitives of the procedural scenes and vectorised ray casting against them.

World frame: metres, z up, the floor at z = 0, the room's interior spans [0, Lx] x [0, Ly] x [0, H].
A box has a centre, full extents along its own axes and a yaw (rotation about world z). Boxes whose
yaw is a multiple of 90 degrees are turned into yaw-0 boxes with swapped extents when packed, so
most of a scene is tested in the fast axis-aligned group.

Every ray of one view starts at the camera centre, so each slab offset ``(bound - origin)`` is a
per-box constant and one slab test costs a multiply per axis and side. Ray directions need not be
unit length: with ``dirs = R K^-1 [u, v, 1]`` the hit parameter ``t`` is the camera z-depth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sray.data_tools.synth.materials import Material


@dataclass(frozen=True)
class Box:
    """One oriented box of a scene (or of an object, in the object's own frame)."""

    center: tuple[float, float, float]
    """Centre in metres."""
    size: tuple[float, float, float]
    """Full extents along the box's local x, y, z (metres, all > 0)."""
    label: int
    """Class id of the scene's label space (IGNORE_ID for props outside it)."""
    material: Material
    """Surface appearance (pattern, colours); evaluated in the box's local frame."""
    yaw: float = 0.0
    """Rotation about world z in radians."""
    casts_shadow: bool = True
    """False for light fixtures, which would otherwise shadow their own light."""


def place(boxes: list[Box], x: float, y: float, yaw: float, z: float = 0.0) -> list[Box]:
    """Move boxes built in an object frame to world position (x, y, z) turned by ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    out = []
    for b in boxes:
        bx, by, bz = b.center
        out.append(Box(center=(x + c * bx - s * by, y + s * bx + c * by, z + bz), size=b.size,
                       label=b.label, material=b.material, yaw=b.yaw + yaw,
                       casts_shadow=b.casts_shadow))
    return out


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
    """Structure-of-arrays form of a box list, grouped by yaw for the ray caster."""

    center: np.ndarray
    """float64 (P, 3)."""
    half: np.ndarray
    """float64 (P, 3) half extents in the box frame (after folding quarter turns)."""
    yaw: np.ndarray
    """float64 (P,) residual yaw (0 for axis-aligned boxes)."""
    quarter: np.ndarray
    """int64 (P,) quarter turns folded into ``half``; keeps textures attached to the object frame."""
    label: np.ndarray
    """int64 (P,)."""
    casts_shadow: np.ndarray
    """bool (P,)."""
    materials: list[Material]
    """Per-box material, index-aligned."""

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
        rel = points - self.center[index]
        c, s = np.cos(self.yaw[index]), np.sin(self.yaw[index])
        return np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1], rel[:, 2]], axis=1)

    def overlaps(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """bool (P,): the box's world-axis bounding box meets the region [lo, hi] (each (3,))."""
        c, s = np.abs(np.cos(self.yaw)), np.abs(np.sin(self.yaw))
        ext = np.stack([c * self.half[:, 0] + s * self.half[:, 1], s * self.half[:, 0] + c * self.half[:, 1],
                        self.half[:, 2]], axis=1)
        return np.all((self.center + ext >= lo) & (self.center - ext <= hi), axis=1)

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """bool (N, P): point n lies inside box p grown by ``margin`` on every side."""
        rel = points[:, None, :] - self.center[None, :, :]
        c, s = np.cos(self.yaw)[None, :], np.sin(self.yaw)[None, :]
        local = np.stack([c * rel[..., 0] + s * rel[..., 1], -s * rel[..., 0] + c * rel[..., 1], rel[..., 2]], -1)
        return np.all(np.abs(local) <= self.half[None, :, :] + margin, axis=2)


def _rotate_z(v: np.ndarray, yaw: float) -> np.ndarray:
    """World vectors (N, 3) expressed in a frame turned by ``yaw`` about z."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]], axis=1)


def _safe_inverse(d: np.ndarray) -> np.ndarray:
    """1 / d with exact zeros nudged to a tiny signed value (float32 (N, 3))."""
    d = np.where(np.abs(d) < 1e-12, 1e-12, d)
    return (1.0 / d).astype(np.float32)


def cast_rays(origin: np.ndarray, dirs: np.ndarray, boxes: PackedBoxes, active: np.ndarray | None = None,
              t_min: float = 1e-4, chunk: int = 8192) -> tuple[np.ndarray, np.ndarray]:
    """Nearest box hit of rays from one origin: (t float32 (N,), box index int64 (N,)).

    origin: (3,) shared ray origin; dirs: (N, 3), any length; active: bool (P,) boxes to test
    (default all). Hits with t <= t_min (origin inside or on a box) are ignored; misses give
    t = inf and index -1.
    """
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
        inv = _safe_inverse(_rotate_z(dirs, yaw))
        o_local = _rotate_z((origin[None, :] - boxes.center[idx]), yaw)
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
    """Exit of rays from inside the room's interior box: (t float32 (N,), face int64 (N,)).

    Faces: 0 = x=0 wall, 1 = x=Lx wall, 2 = y=0 wall, 3 = y=Ly wall, 4 = floor, 5 = ceiling.
    """
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
    c, s = np.cos(boxes.yaw[index]), np.sin(boxes.yaw[index])
    world = np.stack([c * n_local[:, 0] - s * n_local[:, 1], s * n_local[:, 0] + c * n_local[:, 1],
                      n_local[:, 2]], axis=1)
    return world.astype(np.float32), axis
