"""The catalog of a room's furniture: recipes ask for "a table" or "a chair", the catalog draws a shape template
(weights favour common shapes) and stands clutter on usable tops (cups, vases, bottles, books, boxes, plants, lamps),
ignore-labelled like ScanNet's small objects (real tables are never bare)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import fittings as fx
from sray.data_tools.synth import furniture as fu
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth import templates as tp
from sray.data_tools.synth.furniture import CLS, Piece, span
from sray.data_tools.synth.geometry import Box

Rect = tuple[float, float, float, float]  # (x0, x1, y0, y1) in the piece's object frame, metres


def _object(rng: np.random.Generator, x: float, y: float, z: float) -> tuple[list[Box], float]:
    """One small object standing at (x, y) on height z: (its boxes, its footprint's half side)."""
    kind = int(rng.integers(7))
    if kind == 0:    # cup or mug
        s, h, m = float(rng.uniform(0.035, 0.05)), float(rng.uniform(0.08, 0.12)), mat.ceramic(rng)
        return [span(IGNORE_ID, m, x - s, x + s, y - s, y + s, z, z + h)], s
    if kind == 1:    # vase
        s, h = float(rng.uniform(0.05, 0.08)), float(rng.uniform(0.18, 0.35))
        m = mat.ceramic(rng) if rng.random() < 0.5 else mat.painted(rng)
        return [span(IGNORE_ID, m, x - s, x + s, y - s, y + s, z, z + h)], s
    if kind == 2:    # bottle: body and neck
        s, h, m = float(rng.uniform(0.03, 0.045)), float(rng.uniform(0.16, 0.26)), mat.painted(rng)
        return [span(IGNORE_ID, m, x - s, x + s, y - s, y + s, z, z + h),
                span(IGNORE_ID, m, x - 0.012, x + 0.012, y - 0.012, y + 0.012, z + h, z + h + 0.07)], s
    if kind == 3:    # stack of books or magazines
        sx, sy, h = float(rng.uniform(0.08, 0.14)), float(rng.uniform(0.1, 0.16)), float(rng.uniform(0.02, 0.12))
        return [span(IGNORE_ID, mat.painted(rng), x - sx, x + sx, y - sy, y + sy, z, z + h)], max(sx, sy)
    if kind == 4:    # storage box
        s, h = float(rng.uniform(0.07, 0.16)), float(rng.uniform(0.06, 0.2))
        m = mat.fabric(rng) if rng.random() < 0.5 else mat.painted(rng)
        return [span(IGNORE_ID, m, x - s, x + s, y - s, y + s, z, z + h)], s
    if kind == 5:    # potted plant: pot and foliage
        s, h = float(rng.uniform(0.05, 0.09)), float(rng.uniform(0.08, 0.16))
        f, fh = s * float(rng.uniform(1.3, 2.0)), float(rng.uniform(0.15, 0.4))
        return [span(IGNORE_ID, mat.ceramic(rng), x - s, x + s, y - s, y + s, z, z + h),
                span(IGNORE_ID, mat.foliage(rng), x - f, x + f, y - f, y + f, z + h, z + h + fh)], f
    s, stem = float(rng.uniform(0.08, 0.14)), float(rng.uniform(0.25, 0.45))   # table lamp: base, stem, shade
    base = mat.metal(rng)
    return [span(IGNORE_ID, base, x - 0.06, x + 0.06, y - 0.06, y + 0.06, z, z + 0.03),
            span(IGNORE_ID, base, x - 0.01, x + 0.01, y - 0.01, y + 0.01, z + 0.03, z + stem),
            span(IGNORE_ID, mat.fabric(rng), x - s, x + s, y - s, y + s, z + stem, z + stem + 0.18)], s


def top_surface(piece: Piece, label: int) -> tuple[Rect, float]:
    """The top rectangle and height of the highest box of ``piece`` labelled ``label``."""
    boxes = [b for b in piece.boxes if b.label == label]
    if not boxes:
        raise ValueError(f"the piece has no box labelled {label}")
    b = max(boxes, key=lambda b: b.center[2] + b.size[2] / 2)
    (cx, cy, cz), (sx, sy, sz) = b.center, b.size
    return (cx - sx / 2, cx + sx / 2, cy - sy / 2, cy + sy / 2), cz + sz / 2


def add_clutter(rng: np.random.Generator, piece: Piece, label: int, count: int, edge: float = 0.04) -> None:
    """Stand up to ``count`` small objects on the top of ``piece``'s ``label`` box (6 tries each), overlapping neither
    each other nor a taller box of the piece. Its height grows to its tallest object (to keep windows clear)."""
    (x0, x1, y0, y1), z = top_surface(piece, label)
    if x1 - x0 < 2 * edge + 0.1 or y1 - y0 < 2 * edge + 0.1:
        return
    taken: list[Rect] = [(b.center[0] - b.size[0] / 2, b.center[0] + b.size[0] / 2, b.center[1] - b.size[1] / 2,
                          b.center[1] + b.size[1] / 2) for b in piece.boxes if b.center[2] + b.size[2] / 2 > z + 1e-3]
    for _ in range(count):
        for _ in range(6):
            x, y = float(rng.uniform(x0 + edge, x1 - edge)), float(rng.uniform(y0 + edge, y1 - edge))
            boxes, half = _object(rng, x, y, z)
            rect = (x - half, x + half, y - half, y + half)
            inside = x0 <= rect[0] and rect[1] <= x1 and y0 <= rect[2] and rect[3] <= y1
            if inside and all(rect[1] <= a0 or a1 <= rect[0] or rect[3] <= b0 or b1 <= rect[2]
                              for a0, a1, b0, b1 in taken):
                piece.boxes.extend(boxes)
                piece.height = max(piece.height, max(b.center[2] + b.size[2] / 2 for b in boxes))
                taken.append(rect)
                break


def _pick(rng: np.random.Generator, options: list[tuple[float, Callable[[], Piece]]]) -> Piece:
    """Build one of the weighted options (weights need not sum to 1)."""
    weights = np.array([w for w, _ in options])
    return options[int(rng.choice(len(options), p=weights / weights.sum()))][1]()


def _cluttered(rng: np.random.Generator, piece: Piece, label: int, prob: float, most: int) -> Piece:
    """``piece`` with up to ``most`` small objects on its top, with probability ``prob``."""
    if rng.random() < prob:
        add_clutter(rng, piece, label, int(rng.integers(1, most + 1)))
    return piece


def table(rng: np.random.Generator, w: float, d: float, h: float | None = None) -> Piece:
    """A table on four legs, a pedestal or trestles, often with objects on it."""
    options = [(0.5, lambda: fu.table(rng, w, d, h)), (0.25, lambda: tp.pedestal_table(rng, w, d, h))]
    if w >= 0.8:
        options.append((0.25, lambda: tp.trestle_table(rng, w, d, h)))
    return _cluttered(rng, _pick(rng, options), CLS["table"], 0.7, 4)


def chair(rng: np.random.Generator) -> Piece:
    """A dining or office chair, a stool or a sled-base chair."""
    return _pick(rng, [(0.6, lambda: fu.chair(rng)), (0.2, lambda: tp.stool(rng)), (0.2, lambda: tp.sled_chair(rng))])


def sofa(rng: np.random.Generator, w: float) -> Piece:
    """A straight sofa or an L-shaped sectional."""
    return _pick(rng, [(0.7, lambda: fu.sofa(rng, w)), (0.3, lambda: tp.sectional_sofa(rng, max(w, 1.9)))])


def bed(rng: np.random.Generator, w: float, length: float) -> Piece:
    """A framed bed or a low platform bed."""
    return _pick(rng, [(0.6, lambda: fu.bed(rng, w, length)), (0.4, lambda: tp.platform_bed(rng, w, length))])


def bookshelf(rng: np.random.Generator, w: float) -> Piece:
    """A shelved bookcase, an open cube shelf or an open shelving unit."""
    return _pick(rng, [(0.5, lambda: fu.bookshelf(rng, w)), (0.25, lambda: tp.cube_shelf(rng, w)),
                       (0.25, lambda: tp.open_shelf(rng, w))])


def cabinet(rng: np.random.Generator, w: float, d: float, h: float) -> Piece:
    """A door cabinet or (up to chest height) a chest of drawers; low ones often carry objects."""
    options = [(0.6, lambda: fu.cabinet(rng, w, d, h))]
    if h < 1.4:
        options.append((0.4, lambda: tp.drawer_chest(rng, w, d, h)))
    return _cluttered(rng, _pick(rng, options), CLS["cabinet"], 0.6 if h < 1.3 else 0.0, 3)


def desk(rng: np.random.Generator, w: float) -> Piece:
    """A desk (monitor or not), usually with objects on it."""
    return _cluttered(rng, fu.desk(rng, w), CLS["desk"], 0.8, 3)


def counter_run(rng: np.random.Generator, length: float, sink_at: float | None) -> Piece:
    """Kitchen base cabinets and worktop, with objects on the worktop."""
    return _cluttered(rng, fx.counter_run(rng, length, sink_at), CLS["counter"], 0.8, 5)


def refrigerator(rng: np.random.Generator) -> Piece:
    """A one-door fridge, a side-by-side or an under-counter fridge."""
    return _pick(rng, [(0.5, lambda: fx.refrigerator(rng)), (0.35, lambda: tp.side_by_side_fridge(rng)),
                       (0.15, lambda: tp.mini_fridge(rng))])


def door(rng: np.random.Generator, w: float, h: float) -> Piece:
    """A plain or panelled door, a glazed door or a sliding plank door (a double door: ``templates.double_door``)."""
    return _pick(rng, [(0.6, lambda: fx.door(rng, w, h)), (0.25, lambda: tp.glazed_door(rng, w, h)),
                       (0.15, lambda: tp.plank_door(rng, w, h))])


def toilet(rng: np.random.Generator) -> Piece:
    """A floor-standing or wall-hung toilet."""
    return _pick(rng, [(0.65, lambda: fx.toilet(rng)), (0.35, lambda: tp.wall_hung_toilet(rng))])
