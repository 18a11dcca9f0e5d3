"""Procedural albedo of a point in its surface's own 3D frame: it depends on the point, its face and its material,
never on the camera. Noise is hash-based value noise on an integer lattice (uint32 arithmetic, identical everywhere)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.data_tools.synth import materials as mat


def hash01(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """uint32 hash of integer lattice coordinates and a per-point seed (all (N,)), mapped to float32 [0, 1)."""
    h = (seed.astype(np.uint32) ^ (ix.astype(np.uint32) * np.uint32(0x8DA6B343))
         ^ (iy.astype(np.uint32) * np.uint32(0xD8163841)) ^ (iz.astype(np.uint32) * np.uint32(0xCB1AB31F)))
    h ^= h >> np.uint32(16)
    h *= np.uint32(0x7FEB352D)
    h ^= h >> np.uint32(15)
    h *= np.uint32(0x846CA68B)
    h ^= h >> np.uint32(16)
    return (h >> np.uint32(8)).astype(np.float32) / np.float32(1 << 24)


def value_noise(p: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Smooth value noise in [0, 1] at points p (N, 3) with per-point seeds (N,)."""
    f = np.floor(p)
    i = f.astype(np.int64)
    w = (p - f).astype(np.float32)
    w = w * w * (3.0 - 2.0 * w)
    out = np.zeros(len(p), np.float32)
    for dx in (0, 1):
        wx = w[:, 0] if dx else 1.0 - w[:, 0]
        for dy in (0, 1):
            wy = w[:, 1] if dy else 1.0 - w[:, 1]
            for dz in (0, 1):
                wz = w[:, 2] if dz else 1.0 - w[:, 2]
                out += wx * wy * wz * hash01(i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz, seed)
    return out


def fbm(p: np.ndarray, seed: np.ndarray, octaves: int = 3) -> np.ndarray:
    """Fractal sum of value noise, normalised to [0, 1]; p (N, 3), seed (N,)."""
    total = np.zeros(len(p), np.float32)
    amp, norm = 1.0, 0.0
    for o in range(octaves):
        total += amp * value_noise(p * (2.0**o), seed + np.uint32(977 * (o + 1)))
        norm += amp
        amp *= 0.5
    return total / norm


_COLUMNS = (("kind", np.int64), ("color_a", np.float32), ("color_b", np.float32), ("scale", np.float32),
            ("contrast", np.float32), ("axis", np.int64), ("variant", np.int64), ("seed", np.uint32))


@dataclass
class MaterialTable:
    """The materials of S surfaces (index-aligned with what a hit can name) as arrays: colours float32 (S, 3) linear
    RGB, ``scale`` and ``contrast`` float32 (S,), ``seed`` uint32 (S,), the others int64 (S,), ``axis`` in the
    surface's local frame; ``half`` float32 (S, 3) is the surface's box's half extents (grain, panel seams)."""

    kind: np.ndarray
    color_a: np.ndarray
    color_b: np.ndarray
    scale: np.ndarray
    contrast: np.ndarray
    axis: np.ndarray
    variant: np.ndarray
    seed: np.ndarray
    half: np.ndarray

    @classmethod
    def build(cls, materials: list[mat.Material], halves: np.ndarray, quarters: np.ndarray) -> MaterialTable:
        """Pack materials; a quarter-turned box swaps the x/y pattern axis to stay on the object."""
        table = {name: np.array([getattr(m, name) for m in materials], dtype) for name, dtype in _COLUMNS}
        odd = (quarters % 2 == 1) & (table["axis"] < 2)
        table["axis"] = np.where(odd, 1 - table["axis"], table["axis"])
        return cls(**table, half=np.asarray(halves, np.float32))


def _mix(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    return a + (b - a) * t[:, None]


def _pick(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    return q[np.arange(len(q)), axis]


def _tangents(q: np.ndarray, normal_axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two in-face coordinates (u, v) of points on faces with the given normal axis."""
    u_axis = np.where(normal_axis == 0, 1, 0)
    v_axis = np.where(normal_axis == 2, 1, 2)
    return _pick(q, u_axis), _pick(q, v_axis)


def _pattern(kind: int, q: np.ndarray, n_axis: np.ndarray, m: dict[str, np.ndarray]) -> np.ndarray:
    """Albedo (N, 3) of one pattern kind for points q (N, 3) in their surfaces' frames."""
    a, b, scale, contrast, seed = m["color_a"], m["color_b"], m["scale"], m["contrast"], m["seed"]
    one = np.ones(len(q), np.float32)
    if kind == mat.PAINT:
        return a * (1.0 + contrast * (2.0 * fbm(q * scale[:, None], seed) - 1.0))[:, None]
    if kind == mat.WOOD:
        grain = np.argmax(m["half"], axis=1)
        across = _pick(q, (grain + 1) % 3) + 0.6 * _pick(q, (grain + 2) % 3)
        stretch = np.full(q.shape, 8.0, np.float32)
        stretch[np.arange(len(q)), grain] = 1.2
        warp = fbm(q * stretch, seed, 2)
        ring = (0.5 + 0.5 * np.sin(2 * np.pi * (across * scale + 2.5 * warp))) ** 3
        fine = value_noise(q * 60.0, seed + np.uint32(5))
        return _mix(a, b, contrast * ring) * (0.95 + 0.1 * fine)[:, None]
    if kind == mat.PLANKS:
        u, v = _tangents(q, n_axis)
        pw = 1.0 / scale
        row = np.floor(v / pw)
        offset = hash01(row.astype(np.int64), one.astype(np.int64), one.astype(np.int64), seed) * 1.4
        col = np.floor((u + offset) / 1.4)
        tone = hash01(row.astype(np.int64), col.astype(np.int64), one.astype(np.int64) * 7, seed)
        grain_p = np.stack([u * 1.5, v * 25.0, one], axis=1)
        grain = 0.5 + 0.5 * np.sin(2 * np.pi * (v * 30.0 + 3.0 * fbm(grain_p, seed, 2)))
        c = _mix(a, b, contrast * tone) * (0.92 + 0.16 * grain)[:, None]
        seam = ((v / pw) % 1.0 < 0.03) | (((u + offset) / 1.4) % 1.0 < 0.005)
        return np.where(seam[:, None], c * 0.5, c)
    if kind == mat.TILES:
        u, v = _tangents(q, n_axis)
        fu, fv = u * scale, v * scale
        bond = m["variant"] == mat.RUNNING_BOND
        fv = np.where(bond, fv * 2.0, fv)                      # bricks: rows half as tall as they are long
        fu = np.where(bond & (np.floor(fv) % 2 == 1), fu + 0.5, fu)
        iu, iv = np.floor(fu).astype(np.int64), np.floor(fv).astype(np.int64)
        jitter = hash01(iu, iv, iu * 0 + 3, seed)
        checker = (m["variant"] == 1) & ((iu + iv) % 2 == 1)
        c = np.where(checker[:, None], b, a) * (1.0 + contrast * (2.0 * jitter - 1.0))[:, None]
        g = 0.008 * scale
        grout = (fu % 1.0 < g) | (fu % 1.0 > 1 - g) | (fv % 1.0 < g) | (fv % 1.0 > 1 - g)
        grout_col = np.where((m["variant"] == 1)[:, None], 0.3 * (a + b), 0.6 * b)
        return np.where(grout[:, None], grout_col, c)
    if kind == mat.FABRIC:
        weave = fbm(q * scale[:, None], seed, 2)
        mottle = fbm(q * 2.5, seed + np.uint32(11), 2)
        c = _mix(a, b, contrast * mottle) * (0.85 + 0.3 * weave)[:, None]
        u, v = _tangents(q, n_axis)
        plaid = (m["variant"] == 1) & (((u * 4.0) % 1.0 < 0.25) ^ ((v * 4.0) % 1.0 < 0.25))
        return np.where(plaid[:, None], _mix(c, b, 0.6 * one), c)
    if kind == mat.STRIPES:
        x = _pick(q, m["axis"])
        band = ((x * scale) % 1.0 < 0.5).astype(np.float32)
        c = _mix(a, b, contrast * band)
        folds = np.where(m["variant"] == 1, 0.8 + 0.2 * np.sin(2 * np.pi * x * 9.0), 1.0)
        return c * (folds * (0.95 + 0.1 * fbm(q * 20.0, seed, 1)))[:, None]
    if kind == mat.PANELS:
        x = _pick(q, m["axis"]) + _pick(m["half"], m["axis"])
        length = 2.0 * _pick(m["half"], m["axis"])
        n_panels = np.maximum(1.0, np.round(length * scale))
        frac = (x / (length / n_panels)) % 1.0
        dist = np.minimum(frac, 1.0 - frac) * (length / n_panels)
        c = a * (1.0 + contrast * (2.0 * fbm(q * 4.0, seed, 2) - 1.0))[:, None]
        seam = (dist < 0.006) & (x > 0.01) & (x < length - 0.01)
        return np.where(seam[:, None], b, c)
    if kind == mat.SKY:
        height = (q[:, 2] + m["half"][:, 2]) / (2.0 * m["half"][:, 2])
        horizon = 0.18 + 0.2 * fbm(np.stack([q[:, 0] * 3.0 + q[:, 1] * 3.0, one, one], 1), seed, 2)
        clouds = fbm(q * 3.0, seed + np.uint32(3), 3)
        sky = _mix(b, a, np.clip(height, 0, 1)) + (contrast * np.clip(clouds - 0.5, 0, 1))[:, None]
        ground = np.array([0.08, 0.14, 0.06], np.float32) * (0.6 + 0.8 * clouds)[:, None]
        return np.where((height < horizon)[:, None], ground, sky)
    if kind == mat.PAINTING:
        n1 = fbm(q * scale[:, None], seed, 3)
        n2 = fbm(q * scale[:, None] * 0.5 + 7.1, seed + np.uint32(9), 2)
        c = _mix(a, b, np.clip((n1 - 0.3) / 0.4, 0, 1))
        return c * (1.0 - contrast * 0.6 + contrast * 1.2 * n2)[:, None]
    if kind == mat.BOOKS:
        x = _pick(q, m["axis"]) * scale
        spine = np.floor(x).astype(np.int64)
        zero = spine * 0
        col = np.stack([hash01(spine, zero + k, zero, seed) for k in range(3)], axis=1)
        col = (0.15 + 0.75 * col) ** 2.2
        tall = 0.65 + 0.35 * hash01(spine, zero + 3, zero, seed)
        height = (q[:, 2] + m["half"][:, 2]) / (2.0 * m["half"][:, 2])
        gap = (x % 1.0) < 0.08
        return np.where(((height > tall) | gap)[:, None], b, col)
    if kind == mat.LAMP:
        return a.copy()
    if kind == mat.MARBLE:
        warp = fbm(q * scale[:, None], seed, 3)
        vein = np.abs(np.sin(2 * np.pi * (q[:, 0] + 0.7 * q[:, 1] + 0.4 * q[:, 2] + 2.0 * warp)))
        return _mix(a, b, contrast * (1.0 - vein) ** 6) * (0.94 + 0.12 * warp)[:, None]
    raise ValueError(f"unknown material kind {kind}")


def albedo(table: MaterialTable, surface: np.ndarray, q: np.ndarray, normal_axis: np.ndarray) -> np.ndarray:
    """Linear RGB albedo float32 (N, 3) of points q (N, 3), in metres in the frames of their surfaces ``surface``
    (N,); normal_axis (N,) is the local axis the hit face is perpendicular to (planks and tiles lie in that face)."""
    out = np.zeros((len(q), 3), np.float32)
    kinds = table.kind[surface]
    for kind in np.unique(kinds):
        sel = np.flatnonzero(kinds == kind)
        fields = {name: column[surface[sel]] for name, column in vars(table).items()}
        out[sel] = _pattern(int(kind), q[sel].astype(np.float32), normal_axis[sel], fields)
    return np.clip(out, 0.0, 1.0)
