"""The catalog of a room's furniture: room recipes ask for "a table" or "a chair"; the catalog draws the shape
template that builds it (weights favour the common shapes) and stands small objects on a usable top (``clutter.py``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from sray.data_tools.synth import fittings as fx
from sray.data_tools.synth import furniture as fu
from sray.data_tools.synth import templates as tp
from sray.data_tools.synth.clutter import add_clutter
from sray.data_tools.synth.furniture import CLS, Piece


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
    piece = _pick(rng, options)
    return _cluttered(rng, piece, CLS["table"], 0.7, 4)


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
    piece = _pick(rng, options)
    return _cluttered(rng, piece, CLS["cabinet"], 0.6 if h < 1.3 else 0.0, 3)


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
    """A plain or panelled door, a glazed door or a sliding plank door (a double door: ``content.double_door``)."""
    return _pick(rng, [(0.6, lambda: fx.door(rng, w, h)), (0.25, lambda: tp.glazed_door(rng, w, h)),
                       (0.15, lambda: tp.plank_door(rng, w, h))])


def toilet(rng: np.random.Generator) -> Piece:
    """A floor-standing or wall-hung toilet."""
    return _pick(rng, [(0.65, lambda: fx.toilet(rng)), (0.35, lambda: tp.wall_hung_toilet(rng))])
