"""Rotations for camera paths: unit quaternions (numpy float64 (4,), ordered (w, x, y, z)), SLERP, rigidity."""

from __future__ import annotations

import numpy as np

RIGID_TOLERANCE = 1e-3
"""Largest accepted deviation of a pose from rigid: max |R^T R - I|, |det R - 1| and the last row's error."""


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) (w, x, y, z), w >= 0, of a rotation matrix (3, 3). Row i of ``outer`` is 4 q_i q: that
    of the largest component (read off the trace or a diagonal entry) gives q without dividing by a small number."""
    m = np.asarray(rotation, np.float64)
    tr = np.trace(m)
    outer = np.array([
        [1.0 + tr, m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]],
        [m[2, 1] - m[1, 2], 1.0 + m[0, 0] - m[1, 1] - m[2, 2], m[0, 1] + m[1, 0], m[0, 2] + m[2, 0]],
        [m[0, 2] - m[2, 0], m[0, 1] + m[1, 0], 1.0 + m[1, 1] - m[0, 0] - m[2, 2], m[1, 2] + m[2, 1]],
        [m[1, 0] - m[0, 1], m[0, 2] + m[2, 0], m[1, 2] + m[2, 1], 1.0 + m[2, 2] - m[0, 0] - m[1, 1]],
    ])
    i = int(np.argmax((tr, m[0, 0], m[1, 1], m[2, 2])))
    s = 2.0 * np.sqrt(max(outer[i, i], 0.0))
    q = outer[i] / s
    q[i] = 0.25 * s
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a quaternion (4,) (w, x, y, z); normalised first."""
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Quaternions (T, 4) at fractions ``t`` (T,) in [0, 1] of the shorter arc from ``q0`` (4,) to ``q1`` (4,),
    at constant angular speed (t = 1 gives ``q1`` or ``-q1``); nearly equal ones are interpolated linearly."""
    a = np.asarray(q0, np.float64) / np.linalg.norm(q0)
    b = np.asarray(q1, np.float64) / np.linalg.norm(q1)
    t = np.asarray(t, np.float64)[:, None]
    dot = float(a @ b)
    if dot < 0.0:
        b, dot = -b, -dot
    if dot > 1.0 - 1e-12:
        out = (1.0 - t) * a + t * b
        return out / np.linalg.norm(out, axis=1, keepdims=True)
    theta = np.arccos(min(dot, 1.0))
    return (np.sin((1.0 - t) * theta) * a + np.sin(t * theta) * b) / np.sin(theta)


def rotation_angle(r0: np.ndarray, r1: np.ndarray) -> float:
    """Angle in radians of the relative rotation between two rotation matrices (3, 3)."""
    cos = (np.trace(np.asarray(r0, np.float64).T @ np.asarray(r1, np.float64)) - 1.0) / 2.0
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))


def rigid_problem(pose: np.ndarray, tolerance: float = RIGID_TOLERANCE) -> str | None:
    """Why a 4x4 pose is not rigid (finite, last row 0 0 0 1, orthonormal, det +1) within ``tolerance``; else None."""
    m = np.asarray(pose, np.float64)
    if m.shape != (4, 4):
        return f"shape is {m.shape}, not (4, 4)"
    if not np.isfinite(m).all():
        return "holds a non-finite number"
    if float(np.abs(m[3] - (0.0, 0.0, 0.0, 1.0)).max()) > tolerance:
        return f"last row is {m[3].tolist()}, not [0, 0, 0, 1]"
    r = m[:3, :3]
    ortho = float(np.abs(r.T @ r - np.eye(3)).max())
    if ortho > tolerance:
        return f"rotation is not orthonormal (max |R^T R - I| = {ortho:.3g} > {tolerance:g})"
    det = float(np.linalg.det(r))
    if abs(det - 1.0) > tolerance:
        return f"rotation has determinant {det:.3g}, not +1 (a reflection or a scale)"
    return None
