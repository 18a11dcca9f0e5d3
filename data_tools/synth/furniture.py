"""Free-standing furniture assembled from boxes in its object frame: the footprint centred on the origin, z = 0 the
floor, the back at -y and the front (where one sits or opens doors) at +y. ``geometry.place`` puts it in a room."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.data_tools.label_spaces import SCANNET20
from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth.geometry import Box

CLS: dict[str, int] = {name: i for i, name in enumerate(SCANNET20)}
"""ScanNet-20 class id by name."""


@dataclass
class Piece:
    """One object: its boxes (object frame), its footprint's extents along x and y, its top above the floor (m)."""

    boxes: list[Box]
    width: float
    depth: float
    height: float


def span(label: int, material: mat.Material, x0: float, x1: float, y0: float, y1: float,
         z0: float, z1: float, casts_shadow: bool = True) -> Box:
    """An axis-aligned box (object frame) from its extents along x, y and z."""
    return Box(center=((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2), size=(x1 - x0, y1 - y0, z1 - z0),
               label=label, material=material, casts_shadow=casts_shadow)


def legs(label: int, material: mat.Material, w: float, d: float, h: float, leg: float, inset: float) -> list[Box]:
    """Four square legs under a w x d top, from the floor to height h."""
    xs = (-w / 2 + inset, w / 2 - inset - leg)
    ys = (-d / 2 + inset, d / 2 - inset - leg)
    return [span(label, material, x, x + leg, y, y + leg, 0.0, h) for x in xs for y in ys]


def table(rng: np.random.Generator, w: float, d: float, h: float | None = None) -> Piece:
    """A table: top plus four legs (dining, coffee or side table depending on size)."""
    h = float(rng.uniform(0.72, 0.78)) if h is None else h
    surface = mat.furniture_surface(rng)
    legs_mat = surface if rng.random() < 0.6 else mat.metal(rng)
    th, leg = float(rng.uniform(0.025, 0.05)), float(rng.uniform(0.035, 0.07))
    boxes = [span(CLS["table"], surface, -w / 2, w / 2, -d / 2, d / 2, h - th, h)]
    boxes += legs(CLS["table"], legs_mat, w, d, h - th, leg, float(rng.uniform(0.02, 0.08)))
    return Piece(boxes, w, d, h)


def chair(rng: np.random.Generator) -> Piece:
    """A dining chair (seat, back, four legs) or an office chair (column, star base, seat, back)."""
    w, d = float(rng.uniform(0.42, 0.52)), float(rng.uniform(0.42, 0.52))
    seat_h, back_h, label = float(rng.uniform(0.43, 0.5)), float(rng.uniform(0.35, 0.5)), CLS["chair"]
    if rng.random() < 0.35:
        shell, frame = mat.fabric(rng), mat.dark_plastic(rng)
        boxes = [span(label, shell, -w / 2, w / 2, -d / 2, d / 2, seat_h - 0.08, seat_h),
                 span(label, shell, -w / 2, w / 2, -d / 2, -d / 2 + 0.06, seat_h + 0.05, seat_h + back_h + 0.1),
                 span(label, frame, -0.03, 0.03, -0.03, 0.03, 0.06, seat_h - 0.08),
                 span(label, frame, -0.3, 0.3, -0.03, 0.03, 0.02, 0.06),
                 span(label, frame, -0.03, 0.03, -0.3, 0.3, 0.02, 0.06)]
        return Piece(boxes, 0.6, 0.6, seat_h + back_h + 0.1)
    surface = mat.furniture_surface(rng)
    seat_mat = mat.fabric(rng) if rng.random() < 0.4 else surface
    th, leg = float(rng.uniform(0.03, 0.06)), float(rng.uniform(0.03, 0.045))
    boxes = [span(label, seat_mat, -w / 2, w / 2, -d / 2, d / 2, seat_h - th, seat_h),
             span(label, surface, -w / 2, w / 2, -d / 2, -d / 2 + 0.035, seat_h, seat_h + back_h)]
    boxes += legs(label, surface, w, d, seat_h - th, leg, 0.01)
    return Piece(boxes, w, d, seat_h + back_h)


def armchair(rng: np.random.Generator) -> Piece:
    """An upholstered armchair (labelled chair, as ScanNet does): base, seat, back, arms."""
    w, d, cover = float(rng.uniform(0.7, 0.9)), float(rng.uniform(0.75, 0.9)), mat.fabric(rng)
    label, arm = CLS["chair"], float(rng.uniform(0.1, 0.16))
    boxes = [span(label, cover, -w / 2, w / 2, -d / 2, d / 2, 0.08, 0.38),
             span(label, mat.fabric(rng), -w / 2 + arm, w / 2 - arm, -d / 2 + 0.18, d / 2, 0.38, 0.46),
             span(label, cover, -w / 2, w / 2, -d / 2, -d / 2 + 0.18, 0.38, 0.85),
             span(label, cover, -w / 2, -w / 2 + arm, -d / 2, d / 2, 0.38, 0.62),
             span(label, cover, w / 2 - arm, w / 2, -d / 2, d / 2, 0.38, 0.62)]
    return Piece(boxes, w, d, 0.85)


def sofa(rng: np.random.Generator, w: float) -> Piece:
    """A sofa: base on short legs, seat cushions, back rest, two arms; cushions can differ in colour."""
    d, cover = float(rng.uniform(0.85, 1.0)), mat.fabric(rng)
    cushion = cover if rng.random() < 0.6 else mat.fabric(rng)
    label, arm = CLS["sofa"], float(rng.uniform(0.15, 0.25))
    back_h, arm_h = float(rng.uniform(0.78, 0.95)), float(rng.uniform(0.55, 0.68))
    boxes = [span(label, cover, -w / 2, w / 2, -d / 2, d / 2, 0.1, 0.38),
             span(label, cover, -w / 2, w / 2, -d / 2, -d / 2 + 0.22, 0.38, back_h),
             span(label, cover, -w / 2, -w / 2 + arm, -d / 2, d / 2, 0.38, arm_h),
             span(label, cover, w / 2 - arm, w / 2, -d / 2, d / 2, 0.38, arm_h)]
    n, inner = 2 if w < 1.8 else 3, w - 2 * arm
    for i in range(n):
        x0 = -w / 2 + arm + i * inner / n
        boxes.append(span(label, cushion, x0 + 0.01, x0 + inner / n - 0.01, -d / 2 + 0.22, d / 2 - 0.02, 0.38, 0.5))
    boxes += legs(label, mat.dark_plastic(rng), w, d, 0.1, 0.05, 0.05)
    return Piece(boxes, w, d, back_h)


def bed(rng: np.random.Generator, w: float, length: float) -> Piece:
    """A bed: frame, mattress, blanket, headboard, optional footboard; pillows are ignore-labelled."""
    frame_mat, label, frame_top = mat.furniture_surface(rng), CLS["bed"], float(rng.uniform(0.25, 0.38))
    mattress_top = frame_top + float(rng.uniform(0.18, 0.28))
    head_h = float(rng.uniform(0.85, 1.3))
    y0, y1 = -length / 2, length / 2
    boxes = [span(label, frame_mat, -w / 2, w / 2, y0 + 0.06, y1, 0.05, frame_top),
             span(label, mat.fabric(rng), -w / 2 + 0.03, w / 2 - 0.03, y0 + 0.08, y1 - 0.03, frame_top, mattress_top),
             span(label, mat.fabric(rng), -w / 2 + 0.01, w / 2 - 0.01, y0 + 0.65, y1 - 0.01,
                  mattress_top - 0.12, mattress_top + 0.03),
             span(label, frame_mat, -w / 2 - 0.03, w / 2 + 0.03, y0, y0 + 0.06, 0.0, head_h)]
    if rng.random() < 0.4:
        boxes.append(span(label, frame_mat, -w / 2 - 0.03, w / 2 + 0.03, y1 - 0.05, y1, 0.0, mattress_top - 0.05))
    pillow, n = mat.fabric(rng), 1 if w < 1.2 else 2
    for i in range(n):
        x0 = -w / 2 + 0.08 + i * (w - 0.16) / n
        boxes.append(span(IGNORE_ID, pillow, x0 + 0.02, x0 + (w - 0.16) / n - 0.02, y0 + 0.12, y0 + 0.5,
                          mattress_top, mattress_top + 0.13))
    return Piece(boxes, w + 0.06, length, head_h)


def bookshelf(rng: np.random.Generator, w: float) -> Piece:
    """A bookshelf: sides, top, bottom, back panel, shelves; rows of (ignore-labelled) books."""
    d, h = float(rng.uniform(0.28, 0.4)), float(rng.uniform(1.2, 2.1))
    surface, label, th = mat.furniture_surface(rng), CLS["bookshelf"], 0.025
    boxes = [span(label, surface, -w / 2, -w / 2 + th, -d / 2, d / 2, 0, h),
             span(label, surface, w / 2 - th, w / 2, -d / 2, d / 2, 0, h),
             span(label, surface, -w / 2 + th, w / 2 - th, -d / 2, d / 2, h - th, h),
             span(label, surface, -w / 2 + th, w / 2 - th, -d / 2, d / 2, 0, 0.08),
             span(label, surface, -w / 2 + th, w / 2 - th, -d / 2, -d / 2 + 0.012, 0.08, h - th)]
    n = max(2, int((h - 0.1) / float(rng.uniform(0.3, 0.4))))
    step = (h - 0.08 - th) / n
    for i in range(1, n + 1):
        z = 0.08 + i * step
        if i < n:
            boxes.append(span(label, surface, -w / 2 + th, w / 2 - th, -d / 2, d / 2, z - th, z))
        if rng.random() < 0.7:
            fill = float(rng.uniform(0.4, 1.0)) * (w - 2 * th)
            x0 = -w / 2 + th + float(rng.uniform(0, w - 2 * th - fill))
            top = z - th - 0.01 if i < n else z - 0.01
            boxes.append(span(IGNORE_ID, mat.book_row(rng), x0, x0 + fill, -d / 2 + 0.02,
                              d / 2 - float(rng.uniform(0.02, 0.08)), z - step + 0.001, top - 0.02))
    return Piece(boxes, w, d, h)


def cabinet(rng: np.random.Generator, w: float, d: float, h: float) -> Piece:
    """A cabinet (nightstand, wardrobe, file or TV cabinet by size): body, door seams, handles."""
    n_doors = max(1, round(w / 0.5))
    door_w = w / n_doors
    body, label = mat.furniture_surface(rng, panels=True, panel_width=door_w), CLS["cabinet"]
    handle = mat.metal(rng) if rng.random() < 0.6 else mat.dark_plastic(rng)
    boxes = [span(label, body, -w / 2, w / 2, -d / 2, d / 2, 0.0, h)]
    hz = min(h - 0.1, float(rng.uniform(0.9, 1.1))) if h > 1.2 else h * 0.75
    for i in range(n_doors):
        centre = -w / 2 + (i + 0.5) * door_w
        cx = centre + (0.35 * door_w if centre <= 0 else -0.35 * door_w)
        boxes.append(span(label, handle, cx - 0.012, cx + 0.012, d / 2, d / 2 + 0.025, hz - 0.07, hz + 0.07))
    return Piece(boxes, w, d + 0.025, h)


def desk(rng: np.random.Generator, w: float) -> Piece:
    """A desk: top, side panel or legs, a drawer block; a monitor on top (ignore-labelled)."""
    d, h = float(rng.uniform(0.6, 0.8)), float(rng.uniform(0.72, 0.77))
    surface = mat.furniture_surface(rng)
    label, th = CLS["desk"], 0.03
    boxes = [span(label, surface, -w / 2, w / 2, -d / 2, d / 2, h - th, h)]
    if rng.random() < 0.5:
        boxes.append(span(label, surface, -w / 2, -w / 2 + 0.025, -d / 2, d / 2 - 0.03, 0, h - th))
    else:
        boxes += legs(label, surface, w, d, h - th, 0.04, 0.02)[:2]
    drawers = mat.furniture_surface(rng, panels=True, panel_width=0.2) if rng.random() < 0.4 else surface
    boxes.append(span(label, drawers, w / 2 - 0.42, w / 2 - 0.02, -d / 2 + 0.02, d / 2 - 0.02, 0.02, h - th))
    if rng.random() < 0.75:
        screen, mw = mat.dark_plastic(rng), float(rng.uniform(0.45, 0.65))
        boxes += [span(IGNORE_ID, screen, -mw / 2, mw / 2, -d / 2 + 0.12, -d / 2 + 0.15, h + 0.1, h + 0.1 + mw * 0.6),
                  span(IGNORE_ID, screen, -0.03, 0.03, -d / 2 + 0.1, -d / 2 + 0.16, h, h + 0.12)]
    return Piece(boxes, w, d, h)


def other_furniture(rng: np.random.Generator) -> Piece:
    """ScanNet's 'otherfurniture': an ottoman, a bench, a trash can or a side cart."""
    label, pick = CLS["otherfurniture"], rng.random()
    if pick < 0.3:
        s = float(rng.uniform(0.4, 0.6))
        return Piece([span(label, mat.fabric(rng), -s / 2, s / 2, -s / 2, s / 2, 0.0, 0.42)], s, s, 0.42)
    if pick < 0.55:
        w, top = float(rng.uniform(0.8, 1.3)), mat.furniture_surface(rng)
        boxes = [span(label, top, -w / 2, w / 2, -0.18, 0.18, 0.4, 0.45),
                 span(label, top, -w / 2 + 0.03, -w / 2 + 0.07, -0.16, 0.16, 0, 0.4),
                 span(label, top, w / 2 - 0.07, w / 2 - 0.03, -0.16, 0.16, 0, 0.4)]
        return Piece(boxes, w, 0.36, 0.45)
    if pick < 0.8:
        s, h = float(rng.uniform(0.25, 0.35)), float(rng.uniform(0.35, 0.65))
        return Piece([span(label, mat.metal(rng), -s / 2, s / 2, -s / 2, s / 2, 0.0, h)], s, s, h)
    w, h, frame = float(rng.uniform(0.5, 0.8)), float(rng.uniform(0.6, 0.9)), mat.metal(rng)
    boxes = [span(label, frame, -w / 2, w / 2, -0.2, 0.2, z, z + 0.03) for z in (0.1, h / 2, h - 0.03)]
    boxes += legs(label, frame, w, 0.4, h, 0.03, 0.0)
    return Piece(boxes, w, 0.4, h)
