"""Fittings, the built-in pieces of a room: wall fixtures (thin pieces whose back lies on the wall), kitchen and
bathroom pieces, in the object frame of ``furniture.py``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth.furniture import CLS, Piece, span
from sray.data_tools.synth.geometry import Box


def against_wall(boxes: list[Box], width: float, depth: float, height: float) -> Piece:
    """A piece built with its back at y = 0 and its front at y = depth, recentred on its footprint."""
    moved = [replace(b, center=(b.center[0], b.center[1] - depth / 2, b.center[2])) for b in boxes]
    return Piece(moved, width, depth, height)


def casing(material: mat.Material, w: float, h: float, c: float) -> list[Box]:
    """Two jambs and a head, ``c`` wide, around a w x h door opening (labelled door; against-wall frame)."""
    label = CLS["door"]
    return [span(label, material, -w / 2 - c, -w / 2, 0.0, 0.045, 0.0, h + c),
            span(label, material, w / 2, w / 2 + c, 0.0, 0.045, 0.0, h + c),
            span(label, material, -w / 2, w / 2, 0.0, 0.045, h, h + c)]


def door(rng: np.random.Generator, w: float, h: float) -> Piece:
    """A closed door: leaf, casing (two jambs and a head) and a handle, all labelled door."""
    label = CLS["door"]
    leaf = mat.furniture_surface(rng, panels=rng.random() < 0.5, panel_width=w)
    trim = mat.painted(rng) if rng.random() < 0.6 else leaf
    handle, c = mat.metal(rng), float(rng.uniform(0.05, 0.09))
    boxes = [span(label, leaf, -w / 2, w / 2, 0.0, 0.03, 0.0, h), *casing(trim, w, h, c),
             span(label, handle, w / 2 - 0.12, w / 2 - 0.06, 0.03, 0.09, 0.98, 1.02)]
    return against_wall(boxes, w + 2 * c, 0.09, h + c)


def window(rng: np.random.Generator, w: float, sill: float, h: float) -> Piece:
    """A window: emissive daylight glass, frame, mullions and a sill, all labelled window."""
    label = CLS["window"]
    frame = mat.painted(rng) if rng.random() < 0.6 else mat.wood(rng)
    glass = mat.window_glass(rng)
    f, top = float(rng.uniform(0.04, 0.07)), sill + h
    boxes = [span(label, glass, -w / 2, w / 2, 0.0, 0.01, sill, top),
             span(label, frame, -w / 2 - f, -w / 2, 0.0, 0.05, sill, top),
             span(label, frame, w / 2, w / 2 + f, 0.0, 0.05, sill, top),
             span(label, frame, -w / 2 - f, w / 2 + f, 0.0, 0.05, top, top + f),
             span(label, frame, -w / 2 - f - 0.04, w / 2 + f + 0.04, 0.0, 0.1, sill - 0.04, sill)]
    if w > 0.9:
        boxes.append(span(label, frame, -0.02, 0.02, 0.0, 0.035, sill, top))
    if rng.random() < 0.5:
        zm = sill + h * float(rng.uniform(0.55, 0.7))
        boxes.append(span(label, frame, -w / 2, w / 2, 0.0, 0.035, zm - 0.02, zm + 0.02))
    return against_wall(boxes, w + 2 * f + 0.08, 0.1, top + f)


def curtain(rng: np.random.Generator, w: float, z0: float, z1: float, material: mat.Material) -> Piece:
    """One curtain panel hanging in front of a wall, from z0 up to its rod at z1."""
    t = float(rng.uniform(0.04, 0.07))
    return against_wall([span(CLS["curtain"], material, -w / 2, w / 2, 0.1, 0.1 + t, z0, z1)], w, 0.1 + t, z1)


def picture(rng: np.random.Generator, w: float, h: float, z_centre: float) -> Piece:
    """A framed picture: frame and a canvas standing 5 mm proud of it, both labelled picture."""
    label, border = CLS["picture"], float(rng.uniform(0.02, 0.06))
    frame = mat.wood(rng) if rng.random() < 0.5 else mat.painted(rng)
    z0, z1 = z_centre - h / 2, z_centre + h / 2
    boxes = [span(label, frame, -w / 2, w / 2, 0.0, 0.025, z0, z1),
             span(label, mat.canvas(rng), -w / 2 + border, w / 2 - border, 0.0, 0.03, z0 + border, z1 - border)]
    return against_wall(boxes, w, 0.03, z1)


def mirror(rng: np.random.Generator, w: float, h: float, z_centre: float) -> Piece:
    """A wall mirror (ScanNet-20 has no mirror class: ignore-labelled)."""
    glass = mat.Material(mat.PAINT, mat.hsv(rng, (0.5, 0.6), (0.0, 0.1), (0.6, 0.85)), (0, 0, 0),
                         scale=3.0, contrast=0.08, seed=mat.new_seed(rng))
    boxes = [span(IGNORE_ID, glass, -w / 2, w / 2, 0.0, 0.02, z_centre - h / 2, z_centre + h / 2)]
    return against_wall(boxes, w, 0.02, z_centre + h / 2)


def counter_run(rng: np.random.Generator, length: float, sink_at: float | None) -> Piece:
    """Kitchen base cabinets (cabinet) under a worktop (counter), with an optional basin (sink)."""
    depth, top = 0.62, float(rng.uniform(0.88, 0.93))
    doors = mat.painted(rng, panels=True, panel_width=float(rng.uniform(0.4, 0.6)))
    if rng.random() < 0.4:
        doors = mat.wood(rng)
    worktop = mat.wood(rng) if rng.random() < 0.3 else mat.Material(
        mat.PAINT, mat.hsv(rng, (0, 1), (0.0, 0.3), (0.1, 0.95)), (0, 0, 0), scale=float(rng.uniform(8, 25)),
        contrast=float(rng.uniform(0.1, 0.4)), seed=mat.new_seed(rng))
    x0, x1 = -length / 2, length / 2
    boxes = [span(CLS["cabinet"], mat.dark_plastic(rng), x0, x1, 0.0, 0.52, 0.0, 0.1),
             span(CLS["cabinet"], doors, x0, x1, 0.0, 0.58, 0.1, top - 0.04),
             span(CLS["counter"], worktop, x0, x1, 0.0, depth, top - 0.04, top)]
    if sink_at is not None:
        basin, sx = mat.metal(rng), sink_at
        bw, by0, by1, rim = 0.28, 0.12, 0.5, top + 0.14
        boxes += [span(CLS["sink"], basin, sx - bw, sx + bw, by0, by1, top, top + 0.02),
                  span(CLS["sink"], basin, sx - bw, sx + bw, by0, by0 + 0.02, top, rim),
                  span(CLS["sink"], basin, sx - bw, sx + bw, by1 - 0.02, by1, top, rim),
                  span(CLS["sink"], basin, sx - bw, sx - bw + 0.02, by0, by1, top, rim),
                  span(CLS["sink"], basin, sx + bw - 0.02, sx + bw, by0, by1, top, rim),
                  span(CLS["sink"], basin, sx - 0.02, sx + 0.02, 0.04, 0.08, top, top + 0.3),
                  span(CLS["sink"], basin, sx - 0.02, sx + 0.02, 0.04, 0.24, top + 0.27, top + 0.3)]
    return against_wall(boxes, length, depth, top + 0.3)


def wall_cabinets(rng: np.random.Generator, length: float, z0: float, z1: float) -> Piece:
    """Upper kitchen cabinets hung on a wall between heights z0 and z1."""
    body = mat.furniture_surface(rng, panels=True, panel_width=float(rng.uniform(0.35, 0.6)))
    return against_wall([span(CLS["cabinet"], body, -length / 2, length / 2, 0.0, 0.35, z0, z1)], length, 0.35, z1)


def refrigerator(rng: np.random.Generator) -> Piece:
    """A fridge: body with a freezer seam and two handle bars."""
    w, d, h = float(rng.uniform(0.6, 0.9)), float(rng.uniform(0.62, 0.75)), float(rng.uniform(1.65, 1.95))
    label, shell = CLS["refrigerator"], mat.metal(rng)
    handle = mat.dark_plastic(rng) if rng.random() < 0.5 else mat.metal(rng)
    hx = w / 2 - 0.08
    boxes = [span(label, shell, -w / 2, w / 2, 0.0, d, 0.0, h),
             span(label, handle, hx - 0.02, hx + 0.02, d, d + 0.04, h * 0.45, h * 0.62),
             span(label, handle, hx - 0.02, hx + 0.02, d, d + 0.04, h * 0.7, h * 0.85)]
    return against_wall(boxes, w, d + 0.04, h)


def toilet(rng: np.random.Generator) -> Piece:
    """A toilet: pedestal, bowl, seat, cistern and lid (back against the wall)."""
    label, china = CLS["toilet"], mat.ceramic(rng)
    seat = china if rng.random() < 0.6 else mat.ceramic(rng)
    boxes = [span(label, china, -0.21, 0.21, 0.0, 0.18, 0.4, 0.78),
             span(label, china, -0.22, 0.22, -0.01, 0.19, 0.78, 0.8),
             span(label, china, -0.12, 0.12, 0.15, 0.5, 0.0, 0.3),
             span(label, china, -0.18, 0.18, 0.15, 0.68, 0.3, 0.4),
             span(label, seat, -0.19, 0.19, 0.17, 0.7, 0.4, 0.425)]
    return against_wall(boxes, 0.44, 0.7, 0.8)


def washbasin(rng: np.random.Generator, vanity: bool) -> Piece:
    """A bathroom sink on a pedestal (sink) or on a vanity cabinet (cabinet), with a tap."""
    china, w = mat.ceramic(rng), float(rng.uniform(0.5, 0.7))
    top, d = 0.85, 0.48
    boxes: list[Box] = []
    if vanity:
        boxes.append(span(CLS["cabinet"], mat.furniture_surface(rng, panels=True, panel_width=w / 2),
                          -w / 2 - 0.05, w / 2 + 0.05, 0.0, d, 0.0, top - 0.08))
    else:
        boxes.append(span(CLS["sink"], china, -0.1, 0.1, 0.05, 0.25, 0.0, top - 0.08))
    rim, tap = CLS["sink"], mat.metal(rng)
    boxes += [span(rim, china, -w / 2, w / 2, 0.0, d, top - 0.08, top - 0.05),
              span(rim, china, -w / 2, w / 2, 0.0, 0.1, top - 0.05, top),
              span(rim, china, -w / 2, w / 2, d - 0.04, d, top - 0.05, top),
              span(rim, china, -w / 2, -w / 2 + 0.04, 0.0, d, top - 0.05, top),
              span(rim, china, w / 2 - 0.04, w / 2, 0.0, d, top - 0.05, top),
              span(rim, tap, -0.02, 0.02, 0.03, 0.07, top, top + 0.18),
              span(rim, tap, -0.02, 0.02, 0.03, 0.2, top + 0.15, top + 0.18)]
    return against_wall(boxes, w + 0.1, d, top + 0.18)


def bathtub(rng: np.random.Generator, length: float, curtain_side: float | None) -> Piece:
    """An open bathtub (floor, four walls) along a wall; a shower curtain over ``curtain_side`` of its open side."""
    label, china = CLS["bathtub"], mat.ceramic(rng)
    w, h, t = float(rng.uniform(0.7, 0.8)), float(rng.uniform(0.5, 0.6)), 0.07
    boxes = [span(label, china, -length / 2, length / 2, 0.0, w, 0.0, 0.1),
             span(label, china, -length / 2, length / 2, 0.0, t, 0.1, h),
             span(label, china, -length / 2, length / 2, w - t, w, 0.1, h),
             span(label, china, -length / 2, -length / 2 + t, t, w - t, 0.1, h),
             span(label, china, length / 2 - t, length / 2, t, w - t, 0.1, h)]
    top = h
    if curtain_side is not None:
        rod = float(rng.uniform(1.9, 2.05))
        cover = curtain_side * length
        x0 = -length / 2 if rng.random() < 0.5 else length / 2 - cover
        boxes.append(span(CLS["shower curtain"], mat.curtain_fabric(rng), x0, x0 + cover, w - t - 0.05,
                          w - t - 0.03, h * 0.55, rod - 0.03))
        boxes.append(span(IGNORE_ID, mat.metal(rng), -length / 2, length / 2, w - t - 0.055, w - t - 0.025,
                          rod - 0.03, rod))
        top = rod
    return against_wall(boxes, length, w, top)


def ceiling_lamp(rng: np.random.Generator, ceiling: float) -> Piece:
    """A flush ceiling light: an emissive diffuser (ignore-labelled, casts no shadow)."""
    s = float(rng.uniform(0.25, 0.5))
    boxes = [span(IGNORE_ID, mat.lamp_glow(), -s / 2, s / 2, -s / 2, s / 2, ceiling - 0.06, ceiling,
                  casts_shadow=False)]
    return Piece(boxes, s, s, ceiling)
