"""Rugs, kitchen islands, open shelving, under-counter fridges and doors of other styles (object frame of
``furniture.py``), labelled as a ScanNet annotator would: a rug is ``floor`` (docs/data.md, "What is in a room",
says why), an island a ``cabinet`` under a ``counter``, open shelving ``bookshelf``, every door part ``door``.
"""

from __future__ import annotations

import numpy as np

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth.fittings import against_wall, casing
from sray.data_tools.synth.furniture import CLS, Piece, legs, span


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
    """An open shelving unit (labelled bookshelf): four posts and 3-5 shelves, no back, sometimes with boxes or
    books on the shelves (ignore-labelled)."""
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
