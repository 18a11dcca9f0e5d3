"""More shape templates per furniture class (the first is in ``furniture.py`` / ``fittings.py``), same object frame, so
no class has one silhouette; ``catalog.py`` draws one per object. Also rugs (labelled ``floor``: docs/data.md, "What is
in a room") and kitchen islands (a ``cabinet`` under a ``counter``), labelled as a ScanNet annotator would."""

from __future__ import annotations

import numpy as np

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth.fittings import against_wall, casing
from sray.data_tools.synth.furniture import CLS, Piece, legs, span


def pedestal_table(rng: np.random.Generator, w: float, d: float, h: float | None = None) -> Piece:
    """A table on one central column and a flat foot (bistro, cafe or round-looking table)."""
    h = float(rng.uniform(0.72, 0.78)) if h is None else h
    top, stand = mat.furniture_surface(rng), mat.metal(rng) if rng.random() < 0.5 else mat.dark_plastic(rng)
    th, col, foot = float(rng.uniform(0.025, 0.05)), float(rng.uniform(0.06, 0.12)), min(w, d) * 0.6
    label = CLS["table"]
    boxes = [span(label, top, -w / 2, w / 2, -d / 2, d / 2, h - th, h),
             span(label, stand, -col / 2, col / 2, -col / 2, col / 2, 0.03, h - th),
             span(label, stand, -foot / 2, foot / 2, -foot / 2, foot / 2, 0.0, 0.03)]
    return Piece(boxes, w, d, h)


def trestle_table(rng: np.random.Generator, w: float, d: float, h: float | None = None) -> Piece:
    """A table on two solid end panels joined by a stretcher (refectory or desk-like table)."""
    h = float(rng.uniform(0.72, 0.78)) if h is None else h
    top, label = mat.furniture_surface(rng), CLS["table"]
    ends = top if rng.random() < 0.6 else mat.furniture_surface(rng)
    th, inset, panel = float(rng.uniform(0.03, 0.06)), float(rng.uniform(0.08, 0.2)), float(rng.uniform(0.04, 0.08))
    x0, x1 = -w / 2 + inset, w / 2 - inset - panel
    boxes = [span(label, top, -w / 2, w / 2, -d / 2, d / 2, h - th, h),
             span(label, ends, x0, x0 + panel, -d / 2 + 0.06, d / 2 - 0.06, 0.0, h - th),
             span(label, ends, x1, x1 + panel, -d / 2 + 0.06, d / 2 - 0.06, 0.0, h - th),
             span(label, ends, x0 + panel, x1, -0.03, 0.03, 0.12, 0.2)]
    return Piece(boxes, w, d, h)


def stool(rng: np.random.Generator) -> Piece:
    """A backless stool (labelled chair, as ScanNet does): a square seat on four legs with a footrest ring."""
    s, h = float(rng.uniform(0.3, 0.42)), float(rng.uniform(0.45, 0.75))
    wood, leg_mat = mat.furniture_surface(rng), mat.metal(rng) if rng.random() < 0.5 else mat.wood(rng)
    label, leg = CLS["chair"], float(rng.uniform(0.025, 0.04))
    boxes = [span(label, wood, -s / 2, s / 2, -s / 2, s / 2, h - 0.04, h)]
    boxes += legs(label, leg_mat, s, s, h - 0.04, leg, 0.01)
    ring = h * 0.35
    boxes += [span(label, leg_mat, -s / 2 + 0.01, s / 2 - 0.01, -s / 2 + 0.01, -s / 2 + 0.01 + leg, ring, ring + 0.02),
              span(label, leg_mat, -s / 2 + 0.01, s / 2 - 0.01, s / 2 - 0.01 - leg, s / 2 - 0.01, ring, ring + 0.02)]
    return Piece(boxes, s, s, h)


def sled_chair(rng: np.random.Generator) -> Piece:
    """A chair on two floor runners (sled base) with a tall slatted back."""
    w, d, seat_h = float(rng.uniform(0.44, 0.55)), float(rng.uniform(0.46, 0.56)), float(rng.uniform(0.43, 0.48))
    frame, seat = mat.metal(rng), mat.fabric(rng) if rng.random() < 0.5 else mat.furniture_surface(rng)
    label, back_h = CLS["chair"], float(rng.uniform(0.4, 0.6))
    boxes = [span(label, seat, -w / 2, w / 2, -d / 2, d / 2, seat_h - 0.05, seat_h)]
    for x in (-w / 2, w / 2 - 0.025):
        boxes += [span(label, frame, x, x + 0.025, -d / 2, d / 2, 0.0, 0.02),
                  span(label, frame, x, x + 0.025, -d / 2 + 0.02, -d / 2 + 0.045, 0.02, seat_h + back_h),
                  span(label, frame, x, x + 0.025, d / 2 - 0.045, d / 2 - 0.02, 0.02, seat_h - 0.05)]
    n = int(rng.integers(2, 5))
    for i in range(n):
        z = seat_h + 0.08 + i * (back_h - 0.1) / n
        boxes.append(span(label, seat, -w / 2 + 0.025, w / 2 - 0.025, -d / 2 + 0.02, -d / 2 + 0.045, z, z + 0.06))
    return Piece(boxes, w, d, seat_h + back_h)


def sectional_sofa(rng: np.random.Generator, w: float) -> Piece:
    """An L-shaped sofa: a seat run with a chaise at one end and one arm at the other."""
    d, chaise = float(rng.uniform(0.85, 0.95)), float(rng.uniform(1.4, 1.7))
    cover, label = mat.fabric(rng), CLS["sofa"]
    back_h, arm = float(rng.uniform(0.75, 0.9)), float(rng.uniform(0.15, 0.22))
    side = 1.0 if rng.random() < 0.5 else -1.0
    cx0, cx1 = sorted((side * (w / 2 - 0.8), side * w / 2))
    ax0, ax1 = sorted((-side * w / 2, -side * (w / 2 - arm)))
    boxes = [span(label, cover, -w / 2, w / 2, -d / 2, d / 2, 0.08, 0.42),
             span(label, cover, -w / 2, w / 2, -d / 2, -d / 2 + 0.2, 0.42, back_h),
             span(label, cover, ax0, ax1, -d / 2, d / 2, 0.42, 0.6),
             span(label, cover, cx0, cx1, d / 2, -d / 2 + chaise, 0.08, 0.42),
             span(label, mat.fabric(rng), cx0 + 0.02, cx1 - 0.02, -d / 2 + 0.22, -d / 2 + chaise - 0.02, 0.42, 0.5)]
    return Piece(boxes, w, chaise, back_h)


def platform_bed(rng: np.random.Generator, w: float, length: float) -> Piece:
    """A low platform bed: a wide plinth, mattress and blanket, a panel headboard; pillows ignore-labelled."""
    base, label = mat.furniture_surface(rng), CLS["bed"]
    plinth = float(rng.uniform(0.12, 0.25))
    top, head = plinth + float(rng.uniform(0.15, 0.25)), float(rng.uniform(0.5, 0.9))
    boxes = [span(label, base, -w / 2 - 0.1, w / 2 + 0.1, -length / 2, length / 2 + 0.1, 0.0, plinth),
             span(label, mat.fabric(rng), -w / 2, w / 2, -length / 2 + 0.05, length / 2, plinth, top),
             span(label, mat.fabric(rng), -w / 2 - 0.02, w / 2 + 0.02, -length / 2 + 0.55, length / 2 + 0.02,
                  top - 0.1, top + 0.03),
             span(label, mat.fabric(rng) if rng.random() < 0.5 else base, -w / 2 - 0.1, w / 2 + 0.1,
                  -length / 2, -length / 2 + 0.05, plinth, plinth + head)]
    pillow = mat.fabric(rng)
    for x0 in ([-w / 2 + 0.1] if w < 1.2 else [-w / 2 + 0.1, 0.05]):
        boxes.append(span(IGNORE_ID, pillow, x0, x0 + min(0.6, w / 2 - 0.15), -length / 2 + 0.08,
                          -length / 2 + 0.45, top, top + 0.12))
    return Piece(boxes, w + 0.2, length + 0.1, plinth + head)


def cube_shelf(rng: np.random.Generator, w: float) -> Piece:
    """An open cube bookshelf: a grid of square cubbies, some holding ignore-labelled books or boxes."""
    cell, th, d = float(rng.uniform(0.3, 0.4)), 0.02, float(rng.uniform(0.3, 0.4))
    cols, rows = max(1, round(w / cell)), int(rng.integers(1, 5))
    w, h = cols * cell, rows * cell
    surface, label = mat.furniture_surface(rng), CLS["bookshelf"]
    xs = [min(max(-w / 2 + i * cell - th / 2, -w / 2), w / 2 - th) for i in range(cols + 1)]
    zs = [min(max(j * cell - th / 2, 0.0), h - th) for j in range(rows + 1)]
    boxes = [span(label, surface, x, x + th, -d / 2, d / 2, 0.0, h) for x in xs]
    boxes += [span(label, surface, -w / 2 + th, w / 2 - th, -d / 2, d / 2, z, z + th) for z in zs]
    for j in range(rows):
        for i in range(cols):
            if rng.random() < 0.5:
                x0 = -w / 2 + i * cell + th
                fill = mat.book_row(rng) if rng.random() < 0.6 else mat.fabric(rng)
                boxes.append(span(IGNORE_ID, fill, x0 + 0.01, x0 + cell - 2 * th, -d / 2 + 0.03, d / 2 - 0.03,
                                  j * cell + th, j * cell + cell * float(rng.uniform(0.5, 0.85))))
    return Piece(boxes, w, d, h)


def drawer_chest(rng: np.random.Generator, w: float, d: float, h: float) -> Piece:
    """A chest of drawers (labelled cabinet): a body on short feet, drawer fronts and knobs."""
    body, label = mat.furniture_surface(rng), CLS["cabinet"]
    fronts = body if rng.random() < 0.5 else mat.painted(rng)
    knob = mat.metal(rng) if rng.random() < 0.6 else mat.dark_plastic(rng)
    feet = float(rng.uniform(0.0, 0.12))
    n = max(2, int((h - feet) / float(rng.uniform(0.18, 0.3))))
    boxes = [span(label, body, -w / 2, w / 2, -d / 2, d / 2, feet, h)]
    if feet > 0:
        boxes += [span(label, body, x, x + 0.04, y, y + 0.04, 0.0, feet)
                  for x in (-w / 2 + 0.03, w / 2 - 0.07) for y in (-d / 2 + 0.03, d / 2 - 0.07)]
    step = (h - feet - 0.04) / n
    for i in range(n):
        z0 = feet + 0.02 + i * step
        boxes.append(span(label, fronts, -w / 2 + 0.02, w / 2 - 0.02, d / 2, d / 2 + 0.015, z0 + 0.008,
                          z0 + step - 0.008))
        boxes.append(span(label, knob, -0.04, 0.04, d / 2 + 0.015, d / 2 + 0.035, z0 + step / 2 - 0.012,
                          z0 + step / 2 + 0.012))
    return Piece(boxes, w, d + 0.035, h)


def side_by_side_fridge(rng: np.random.Generator) -> Piece:
    """A wide two-door refrigerator (or a squat under-counter one) with vertical handles."""
    tall = rng.random() < 0.6
    w = float(rng.uniform(0.85, 1.0)) if tall else float(rng.uniform(0.5, 0.6))
    h = float(rng.uniform(1.75, 1.9)) if tall else float(rng.uniform(0.8, 0.9))
    d, label, shell = float(rng.uniform(0.6, 0.75)), CLS["refrigerator"], mat.metal(rng)
    handle = mat.dark_plastic(rng) if rng.random() < 0.5 else mat.metal(rng)
    boxes = [span(label, shell, -w / 2, w / 2, 0.0, d, 0.0, h)]
    xs = (-0.05, 0.03) if tall else (w / 2 - 0.08,)
    boxes += [span(label, handle, x, x + 0.02, d, d + 0.04, h * 0.3, h * 0.8) for x in xs]
    return against_wall(boxes, w, d + 0.04, h)


def wall_hung_toilet(rng: np.random.Generator) -> Piece:
    """A wall-hung toilet: a bowl off the floor, a flush plate on a boxed-in wall frame."""
    label, china = CLS["toilet"], mat.ceramic(rng)
    frame = mat.painted(rng) if rng.random() < 0.5 else china
    boxes = [span(label, frame, -0.3, 0.3, 0.0, 0.15, 0.0, float(rng.uniform(0.9, 1.15))),
             span(label, china, -0.18, 0.18, 0.15, 0.68, 0.22, 0.4),
             span(label, china, -0.18, 0.18, 0.16, 0.68, 0.4, 0.43),
             span(label, mat.metal(rng), -0.1, 0.1, 0.15, 0.16, 0.75, 0.85)]
    return against_wall(boxes, 0.6, 0.68, 1.15)


def rug(rng: np.random.Generator, w: float, d: float) -> Piece:
    """A rug (labelled floor): plain, plaid or striped pile, 8-15 mm thick, casting no shadow."""
    if rng.random() < 0.4:
        pile = mat.fabric(rng)
    else:
        a, b = mat.hsv(rng, (0, 1), (0.1, 0.7), (0.15, 0.85)), mat.hsv(rng, (0, 1), (0.1, 0.7), (0.15, 0.85))
        pile = mat.Material(mat.STRIPES, a, b, scale=float(rng.uniform(2.0, 8.0)),
                            contrast=float(rng.uniform(0.4, 1.0)), axis=int(rng.integers(2)), seed=mat.new_seed(rng))
    t = float(rng.uniform(0.008, 0.015))
    return Piece([span(CLS["floor"], pile, -w / 2, w / 2, -d / 2, d / 2, 0.0, t, casts_shadow=False)], w, d, t)


def kitchen_island(rng: np.random.Generator, w: float, d: float) -> Piece:
    """A free-standing island: a cabinet body on a dark plinth under an overhanging counter top."""
    top = float(rng.uniform(0.88, 0.93))
    body = mat.furniture_surface(rng, panels=True, panel_width=float(rng.uniform(0.4, 0.6)))
    worktop = mat.wood(rng) if rng.random() < 0.4 else mat.painted(rng)
    over = float(rng.uniform(0.03, 0.25))
    boxes = [span(CLS["cabinet"], mat.dark_plastic(rng), -w / 2 + over + 0.05, w / 2 - over - 0.05, -d / 2 + 0.05,
                  d / 2 - 0.05, 0.0, 0.1),
             span(CLS["cabinet"], body, -w / 2 + over, w / 2 - over, -d / 2, d / 2 - over, 0.1, top - 0.04),
             span(CLS["counter"], worktop, -w / 2, w / 2, -d / 2, d / 2, top - 0.04, top)]
    return Piece(boxes, w, d, top)


def open_shelf(rng: np.random.Generator, w: float) -> Piece:
    """An open shelving unit (bookshelf): four posts, 3-5 shelves, no back, some ignore-labelled books or boxes."""
    d, h = float(rng.uniform(0.3, 0.45)), float(rng.uniform(0.9, 1.9))
    frame = mat.metal(rng) if rng.random() < 0.5 else mat.wood(rng)
    shelf = frame if rng.random() < 0.5 else mat.furniture_surface(rng)
    label, post = CLS["bookshelf"], float(rng.uniform(0.025, 0.04))
    boxes = legs(label, frame, w, d, h, post, 0.0)
    n = int(rng.integers(3, 6))
    for i in range(n):
        z = 0.08 + i * (h - 0.1) / (n - 1)
        boxes.append(span(label, shelf, -w / 2, w / 2, -d / 2, d / 2, z - 0.02, z))
        if i < n - 1 and rng.random() < 0.6:
            fill = float(rng.uniform(0.3, 0.9)) * (w - 2 * post)
            x0 = -w / 2 + post + float(rng.uniform(0, w - 2 * post - fill))
            stuff = mat.book_row(rng) if rng.random() < 0.5 else mat.painted(rng)
            boxes.append(span(IGNORE_ID, stuff, x0, x0 + fill, -d / 2 + 0.03, d / 2 - 0.03, z,
                              z + float(rng.uniform(0.4, 0.8)) * (h - 0.1) / (n - 1)))
    return Piece(boxes, w, d, h)


def mini_fridge(rng: np.random.Generator) -> Piece:
    """An under-counter fridge (labelled refrigerator): a cube body with a door seam and a handle."""
    w, d, h = float(rng.uniform(0.45, 0.6)), float(rng.uniform(0.5, 0.6)), float(rng.uniform(0.8, 0.88))
    label = CLS["refrigerator"]
    boxes = [span(label, mat.metal(rng), -w / 2, w / 2, 0.0, d, 0.0, h),
             span(label, mat.dark_plastic(rng), w / 2 - 0.07, w / 2 - 0.04, d, d + 0.03, h * 0.55, h * 0.9)]
    return against_wall(boxes, w, d + 0.03, h)


def glazed_door(rng: np.random.Generator, w: float, h: float) -> Piece:
    """A door with a glass panel in its upper part (stile-and-rail frame; the glass is door-labelled too)."""
    label, frame = CLS["door"], mat.furniture_surface(rng)
    glass = mat.Material(mat.PAINT, mat.hsv(rng, (0.45, 0.6), (0.0, 0.15), (0.55, 0.85)), (0, 0, 0), scale=2.0,
                         contrast=0.05, seed=mat.new_seed(rng))
    c, rail, z0 = float(rng.uniform(0.05, 0.09)), float(rng.uniform(0.08, 0.14)), float(rng.uniform(0.9, 1.1))
    boxes = [span(label, frame, -w / 2, w / 2, 0.0, 0.03, 0.0, z0),
             span(label, frame, -w / 2, -w / 2 + rail, 0.0, 0.03, z0, h),
             span(label, frame, w / 2 - rail, w / 2, 0.0, 0.03, z0, h),
             span(label, frame, -w / 2 + rail, w / 2 - rail, 0.0, 0.03, h - rail, h),
             span(label, glass, -w / 2 + rail, w / 2 - rail, 0.0, 0.015, z0, h - rail),
             span(label, mat.metal(rng), w / 2 - 0.12, w / 2 - 0.06, 0.03, 0.09, 0.98, 1.02),
             *casing(mat.painted(rng) if rng.random() < 0.6 else frame, w, h, c)]
    return against_wall(boxes, w + 2 * c, 0.09, h + c)


def double_door(rng: np.random.Generator, w: float, h: float) -> Piece:
    """Two panelled leaves meeting in the middle, each with a handle by the meeting stiles."""
    label, leaf = CLS["door"], mat.furniture_surface(rng, panels=True, panel_width=w / 2)
    handle, c = mat.metal(rng), float(rng.uniform(0.05, 0.09))
    boxes = [span(label, leaf, -w / 2, -0.004, 0.0, 0.03, 0.0, h), span(label, leaf, 0.004, w / 2, 0.0, 0.03, 0.0, h),
             span(label, handle, -0.1, -0.06, 0.03, 0.09, 0.98, 1.02),
             span(label, handle, 0.06, 0.1, 0.03, 0.09, 0.98, 1.02),
             *casing(mat.painted(rng), w, h, c)]
    return against_wall(boxes, w + 2 * c, 0.09, h + c)


def plank_door(rng: np.random.Generator, w: float, h: float) -> Piece:
    """A sliding plank (barn) door hanging on a rail in front of the wall, wider than its opening."""
    label, a = CLS["door"], mat.hsv(rng, (0.03, 0.12), (0.25, 0.7), (0.2, 0.8))
    planks = mat.Material(mat.PLANKS, a, tuple(min(1.0, v * 0.7) for v in a), scale=float(rng.uniform(5, 9)),
                          contrast=float(rng.uniform(0.3, 0.6)), seed=mat.new_seed(rng))
    rail = mat.dark_plastic(rng)
    boxes = [span(label, planks, -w / 2, w / 2, 0.02, 0.06, 0.01, h),
             span(label, planks, -w / 2, w / 2, 0.06, 0.08, h * 0.45, h * 0.52),
             span(label, rail, -w / 2 - 0.2, w / 2 + 0.2, 0.0, 0.02, h + 0.03, h + 0.07),
             span(label, rail, w / 2 - 0.15, w / 2 - 0.12, 0.08, 0.11, 0.9, 1.2)]
    return against_wall(boxes, w + 0.4, 0.11, h + 0.07)
