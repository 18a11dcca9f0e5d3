"""Handheld-scan-like camera paths (docs/data.md, "Camera paths"): an ellipse arc or a straight walk over free floor,
wobbling in position, height and roll, looking across the room; centres stay in the room, off the walls and out of every
box grown by a margin."""

from __future__ import annotations

import math

import numpy as np

from sray.data_tools.synth import domains
from sray.data_tools.synth.geometry import PackedBoxes, in_frame

HEIGHT_RANGE = (1.0, 1.85)  # camera height band of training scans, metres
WALL_CLEARANCE = 0.35  # least distance of a camera centre from any wall, floor or ceiling, metres
BOX_MARGIN = 0.25  # least distance of a camera centre from every box, metres per axis
BODY_RADIUS = 0.25  # how far the scanning person's standing point keeps from furniture footprints, metres


def look_at(eye: np.ndarray, target: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """float64 (4, 4) camera-to-world in OpenCV axes (x right, y down, z forward); world z is up."""
    forward = target - eye
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, np.array([0.0, 0.0, 1.0]))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    c, s = math.cos(roll), math.sin(roll)
    right, down = c * right + s * down, -s * right + c * down
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, down, forward, eye
    return c2w


def _wobble(rng: np.random.Generator, s: np.ndarray, amplitude: float, cycles: tuple[float, float]) -> np.ndarray:
    """A smooth random signal over path parameter s in [0, 1]: three sines of random phase."""
    out = np.zeros_like(s)
    for k in range(3):
        freq = float(rng.uniform(*cycles))
        out += amplitude / (k + 1) * np.sin(2 * math.pi * freq * s + float(rng.uniform(0, 2 * math.pi)))
    return out


def camera_valid(centres: np.ndarray, size: tuple[float, float, float], boxes: PackedBoxes,
                 standing: bool = False) -> np.ndarray:
    """bool (N,): camera centres (N, 3) inside the room with clearance and outside every grown box; ``standing``:
    also above free floor (off every footprint of a box taller than a rug, grown by :data:`BODY_RADIUS`)."""
    hi = np.asarray(size)
    ok = np.all((centres >= WALL_CLEARANCE) & (centres <= hi - WALL_CLEARANCE), axis=1)
    ok &= ~np.any(boxes.contains(centres, BOX_MARGIN), axis=1)
    if standing:
        tall = (boxes.center[:, 2] + boxes.half[:, 2]) > 0.05
        floor_level = np.concatenate([centres[:, :2], np.zeros((len(centres), 1))], axis=1)
        local = in_frame(floor_level[:, None, :] - boxes.center[None, :, :], np.cos(boxes.yaw), np.sin(boxes.yaw))
        near = np.all(np.abs(local[..., :2]) <= boxes.half[None, :, :2] + BODY_RADIUS, axis=2)  # (N, P) per axis
        ok &= ~np.any(near[:, tall], axis=1)
    return ok


def _arc(rng: np.random.Generator, size: tuple[float, float, float], s: np.ndarray
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Floor positions x, y (n,) and headings (n,) of an arc of an ellipse, looking outward."""
    lx, ly, _ = size
    centre = np.array([rng.uniform(0.35 * lx, 0.65 * lx), rng.uniform(0.35 * ly, 0.65 * ly)])
    a = float(rng.uniform(0.15, max(0.2, min(centre[0], lx - centre[0]) - WALL_CLEARANCE)))
    b = float(rng.uniform(0.15, max(0.2, min(centre[1], ly - centre[1]) - WALL_CLEARANCE)))
    sweep = float(rng.uniform(0.7, 2.0)) * math.pi * float(rng.choice([-1.0, 1.0]))
    theta = float(rng.uniform(0, 2 * math.pi)) + sweep * s
    x = centre[0] + a * np.cos(theta) + _wobble(rng, s, 0.06, (1.5, 5.0))
    y = centre[1] + b * np.sin(theta) + _wobble(rng, s, 0.06, (1.5, 5.0))
    return x, y, theta + math.pi + _wobble(rng, s, 0.45, (0.3, 1.2))


def _walk(rng: np.random.Generator, size: tuple[float, float, float], s: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Floor positions and headings of a straight walk (1-2.5 m) looking to one side of the walking line."""
    lx, ly, _ = size
    start = np.array([rng.uniform(0.3 * lx, 0.7 * lx), rng.uniform(0.3 * ly, 0.7 * ly)])
    direction, length = float(rng.uniform(0, 2 * math.pi)), float(rng.uniform(1.0, 2.5))
    x = start[0] + (s - 0.5) * length * math.cos(direction) + _wobble(rng, s, 0.05, (1.5, 4.0))
    y = start[1] + (s - 0.5) * length * math.sin(direction) + _wobble(rng, s, 0.05, (1.5, 4.0))
    side = float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.35, 1.75))
    return x, y, direction + side + _wobble(rng, s, 0.4, (0.3, 1.0))


def _candidate(rng: np.random.Generator, size: tuple[float, float, float], n_views: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One random path, an arc (70 %) or a walk: eyes (n, 3), look-at targets (n, 3) and roll angles (n,) in
    radians; base height and look-at height are drawn per path (held-out bands in a geometry-shifted room)."""
    lx, ly, _ = size
    shifted = domains.current().geometry_shift
    heights, look = (domains.HELD_OUT_CAMERA, domains.HELD_OUT_LOOK) if shifted else (HEIGHT_RANGE, (0.2, 1.3))
    s = np.linspace(0.0, 1.0, n_views)
    x, y, heading = (_arc if rng.random() < 0.7 else _walk)(rng, size, s)
    z = np.clip(float(rng.uniform(heights[0] + 0.05, heights[1] - 0.1)) + _wobble(rng, s, 0.1, (1.0, 4.0)), *heights)
    dx, dy = np.cos(heading), np.sin(heading)
    with np.errstate(divide="ignore"):
        to_wall = np.minimum(np.where(dx > 0, (lx - x) / dx, -x / dx), np.where(dy > 0, (ly - y) / dy, -y / dy))
    reach = np.maximum(0.6, (to_wall - 0.4) * float(rng.uniform(0.6, 1.0)))
    tz = float(rng.uniform(*look)) + _wobble(rng, s, 0.25, (0.5, 3.0))
    roll = np.radians(_wobble(rng, s, 2.5, (1.0, 4.0)))
    return np.stack([x, y, z], axis=1), np.stack([x + reach * dx, y + reach * dy, tz], axis=1), roll


def scan_path(rng: np.random.Generator, size: tuple[float, float, float], boxes: PackedBoxes,
              n_views: int, attempts: int = 1500) -> np.ndarray:
    """A valid path of ``n_views`` cameras, float64 (n_views, 4, 4) c2w in OpenCV axes; RuntimeError when none is
    found. The first two thirds of the attempts need the person on free floor, the rest may reach over furniture."""
    if n_views < 1:
        raise ValueError(f"n_views must be >= 1, got {n_views}")
    for attempt in range(attempts):
        eyes, targets, roll = _candidate(rng, size, n_views)
        if np.all(camera_valid(eyes, size, boxes, standing=attempt < 2 * attempts // 3)):
            return np.stack([look_at(e, t, r) for e, t, r in zip(eyes, targets, roll)])
    raise RuntimeError(f"no collision-free camera path found in a {size} room after {attempts} attempts")
