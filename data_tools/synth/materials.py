"""Surface materials of the procedural scenes: a pattern kind, two linear RGB colours and a few parameters,
evaluated in the surface's own frame (``textures.py``). Palettes are wide on purpose (any hue for paint, fabric and
curtains; light to dark for wood) so that colour alone does not give a class away."""

from __future__ import annotations

import colorsys
from dataclasses import dataclass

import numpy as np

from sray.data_tools.synth import domains

PAINT, WOOD, PLANKS, TILES, FABRIC, STRIPES, PANELS, SKY, PAINTING, BOOKS, LAMP, MARBLE = range(12)
"""Pattern kinds."""
RUNNING_BOND = 2
"""``TILES`` variant whose every other row is shifted by half a tile (bricks, subway tiles)."""
UNLIT_KINDS = (SKY, LAMP)
"""Emissive kinds: their colour is not shaded."""


@dataclass(frozen=True)
class Material:
    """Appearance of one surface: pattern kind, main and second colour (grain, grout, stripes, seams; linear RGB),
    pattern frequency in cycles per metre, modulation strength 0..1, the object-frame axis a directional pattern runs
    across, a pattern-specific switch (checker tiles, plaid) and a per-surface noise seed."""

    kind: int
    color_a: tuple[float, float, float]
    color_b: tuple[float, float, float]
    scale: float = 1.0
    contrast: float = 0.2
    axis: int = 0
    variant: int = 0
    seed: int = 0


def hsv(rng: np.random.Generator, h: tuple[float, float], s: tuple[float, float],
        v: tuple[float, float], emissive: bool = False) -> tuple[float, float, float]:
    """A linear RGB colour (sRGB ** 2.2) drawn uniformly from an HSV box (hue wraps around); a surface colour (not
    ``emissive``) is then randomised (``domains.jitter_colour``) and kept out of, or moved into, the held-out region."""
    hue, sat, val = float(rng.uniform(*h)) % 1.0, float(rng.uniform(*s)), float(rng.uniform(*v))
    if not emissive:
        hue, sat, val = domains.jitter_colour(rng, hue, sat, val)
        hue, sat = domains.surface_colour(rng, hue, sat)
    return tuple(float(c) ** 2.2 for c in colorsys.hsv_to_rgb(hue, sat, val))  # type: ignore[return-value]


def new_seed(rng: np.random.Generator) -> int:
    """A per-surface noise seed."""
    return int(rng.integers(0, 2**31 - 1))


def _shade(color: tuple[float, float, float], factor: float) -> tuple[float, float, float]:
    return tuple(min(1.0, c * factor) for c in color)  # type: ignore[return-value]


def wood(rng: np.random.Generator) -> Material:
    """Light oak to dark walnut with grain stripes."""
    a = hsv(rng, (0.04, 0.11), (0.35, 0.75), (0.3, 0.85))
    return Material(WOOD, a, _shade(a, rng.uniform(0.55, 0.8)), scale=float(rng.uniform(6, 14)),
                    contrast=float(rng.uniform(0.3, 0.8)), seed=new_seed(rng))


def painted(rng: np.random.Generator, panels: bool = False, panel_width: float = 0.45) -> Material:
    """Any hue, muted to saturated, light to dark; optional door/drawer seams."""
    a = hsv(rng, (0, 1), (0.0, 0.55), (0.25, 0.95))
    return Material(PANELS if panels else PAINT, a, _shade(a, 0.45), scale=1.0 / panel_width,
                    contrast=float(rng.uniform(0.03, 0.12)), seed=new_seed(rng))


def furniture_surface(rng: np.random.Generator, panels: bool = False, panel_width: float = 0.45) -> Material:
    """Wood or paint, as cabinets, shelves and desks come; in an appearance-shifted room also stone (held out)."""
    if domains.current().appearance_shift and rng.random() < 0.4:
        return stone(rng)
    return wood(rng) if rng.random() < 0.5 else painted(rng, panels=panels, panel_width=panel_width)


def fabric(rng: np.random.Generator) -> Material:
    """Upholstery and bedding: any hue; plain weave, mottled or plaid."""
    a = hsv(rng, (0, 1), (0.05, 0.7), (0.2, 0.9))
    b = hsv(rng, (0, 1), (0.05, 0.7), (0.2, 0.9)) if rng.random() < 0.4 else _shade(a, 0.7)
    return Material(FABRIC, a, b, scale=float(rng.uniform(15, 40)), contrast=float(rng.uniform(0.1, 0.5)),
                    variant=int(rng.random() < 0.25), seed=new_seed(rng))


def ceramic(rng: np.random.Generator) -> Material:
    """Sanitary ware: mostly white, sometimes cream, pastel or dark."""
    a = hsv(rng, (0, 1), (0.0, 0.08), (0.82, 0.97)) if rng.random() < 0.7 else hsv(rng, (0, 1), (0.1, 0.5), (0.3, 0.9))
    return Material(PAINT, a, a, scale=3.0, contrast=0.04, seed=new_seed(rng))


METAL_PALETTES = ((0.4, (0.5, 0.7), (0.0, 0.08), (0.55, 0.8)), (0.65, (0, 1), (0.0, 0.05), (0.85, 0.97)),
                  (0.85, (0, 1), (0.0, 0.1), (0.08, 0.25)), (1.0, (0, 1), (0.3, 0.8), (0.4, 0.9)))
"""(cumulative probability, HSV box) of metal finishes: steel, white, black, a colour."""


def metal(rng: np.random.Generator) -> Material:
    """Appliance or fitting finish: steel, white, black or a colour."""
    pick = rng.random()
    box = next(box for top, *box in METAL_PALETTES if pick < top)
    a = hsv(rng, *box)
    return Material(PANELS, a, _shade(a, 0.5), scale=1.0 / 0.7, contrast=0.05, axis=2, seed=new_seed(rng))


def stone(rng: np.random.Generator) -> Material:
    """Marble or granite worktops and vanity tops: light to dark stone with veins."""
    a = hsv(rng, (0, 1), (0.0, 0.2), (0.15, 0.95))
    b = _shade(a, float(rng.uniform(0.3, 0.7))) if rng.random() < 0.6 else hsv(rng, (0, 1), (0.0, 0.2), (0.1, 0.9))
    return Material(MARBLE, a, b, scale=float(rng.uniform(1.5, 6.0)), contrast=float(rng.uniform(0.3, 0.9)),
                    seed=new_seed(rng))


def brick(rng: np.random.Generator) -> Material:
    """Brick, painted brick or subway tiles in running bond (walls)."""
    a = hsv(rng, (0.0, 0.08), (0.35, 0.75), (0.3, 0.7)) if rng.random() < 0.5 else hsv(rng, (0, 1), (0.0, 0.3),
                                                                                         (0.5, 0.95))
    return Material(TILES, a, hsv(rng, (0, 1), (0.0, 0.15), (0.5, 0.9)), scale=float(rng.uniform(3.5, 8.0)),
                    contrast=float(rng.uniform(0.1, 0.3)), variant=RUNNING_BOND, seed=new_seed(rng))


def wall_paint(rng: np.random.Generator) -> Material:
    """Walls: pale paint (any hue) with a soft mottle, striped wallpaper, brick, or wood panelling."""
    a = hsv(rng, (0, 1), (0.0, 0.3), (0.55, 0.95))
    pick = rng.random()
    if pick < 0.1:
        return brick(rng)
    if pick < 0.17:
        b = hsv(rng, (0.03, 0.12), (0.2, 0.7), (0.3, 0.85))
        return Material(PLANKS, b, _shade(b, rng.uniform(0.6, 0.85)), scale=float(rng.uniform(5, 10)),
                        contrast=float(rng.uniform(0.2, 0.5)), seed=new_seed(rng))
    if pick < 0.37:
        b = hsv(rng, (0, 1), (0.0, 0.35), (0.45, 0.95))
        return Material(STRIPES, a, b, scale=float(rng.uniform(2, 8)), contrast=float(rng.uniform(0.3, 1.0)),
                        axis=0, seed=new_seed(rng))
    return Material(PAINT, a, a, scale=float(rng.uniform(1, 4)), contrast=float(rng.uniform(0.05, 0.2)),
                    seed=new_seed(rng))


def floor_surface(rng: np.random.Generator, wet_room: bool = False) -> Material:
    """Floors: parquet, planks, concrete-like paint, carpet or tiles (plain or checker); wet rooms get tiles; most
    floors of an appearance-shifted room get a held-out covering (:func:`held_out_floor`)."""
    if domains.current().appearance_shift and rng.random() < 0.6:
        return held_out_floor(rng)
    pick = 1.0 if wet_room else rng.random()
    if pick < 0.1:  # parquet: squares of two wood tones
        a = hsv(rng, (0.04, 0.11), (0.35, 0.75), (0.3, 0.85))
        return Material(TILES, a, _shade(a, float(rng.uniform(0.6, 0.8))), scale=float(rng.uniform(2.5, 5.0)),
                        contrast=float(rng.uniform(0.1, 0.3)), variant=1, seed=new_seed(rng))
    if pick < 0.45:
        a = hsv(rng, (0.03, 0.12), (0.25, 0.75), (0.25, 0.85))
        return Material(PLANKS, a, _shade(a, rng.uniform(0.6, 0.85)), scale=float(rng.uniform(4, 9)),
                        contrast=float(rng.uniform(0.2, 0.6)), seed=new_seed(rng))
    if pick < 0.55:
        a = hsv(rng, (0, 1), (0.0, 0.12), (0.3, 0.8))
        return Material(PAINT, a, a, scale=float(rng.uniform(2, 6)), contrast=float(rng.uniform(0.15, 0.35)),
                        seed=new_seed(rng))
    if pick < 0.75:
        return Material(FABRIC, hsv(rng, (0, 1), (0.0, 0.5), (0.2, 0.8)), hsv(rng, (0, 1), (0.0, 0.5), (0.2, 0.8)),
                        scale=float(rng.uniform(30, 60)), contrast=float(rng.uniform(0.1, 0.3)), seed=new_seed(rng))
    a = hsv(rng, (0, 1), (0.0, 0.35), (0.35, 0.95))
    checker = int(rng.random() < 0.35)
    b = hsv(rng, (0, 1), (0.0, 0.35), (0.1, 0.95)) if checker else _shade(a, 0.55)
    return Material(TILES, a, b, scale=float(rng.uniform(1.6, 5.0)), contrast=float(rng.uniform(0.05, 0.2)),
                    variant=checker, seed=new_seed(rng))


def held_out_floor(rng: np.random.Generator) -> Material:
    """A floor covering no training room has: a marble floor or a large-pattern plaid carpet (< 10 cycles/m)."""
    if rng.random() < 0.5:
        return stone(rng)
    return Material(FABRIC, hsv(rng, (0, 1), (0.1, 0.7), (0.2, 0.8)), hsv(rng, (0, 1), (0.1, 0.7), (0.2, 0.8)),
                    scale=float(rng.uniform(2.5, 8.0)), contrast=float(rng.uniform(0.3, 0.6)), variant=1,
                    seed=new_seed(rng))


def ceiling_paint(rng: np.random.Generator) -> Material:
    """Ceilings: near-white with a faint mottle."""
    a = hsv(rng, (0, 1), (0.0, 0.06), (0.8, 0.95))
    return Material(PAINT, a, a, scale=2.0, contrast=0.05, seed=new_seed(rng))


def curtain_fabric(rng: np.random.Generator) -> Material:
    """Curtains: any colour, plain with folds or striped across the curtain's width (object x)."""
    a = hsv(rng, (0, 1), (0.05, 0.8), (0.2, 0.92))
    b = hsv(rng, (0, 1), (0.05, 0.8), (0.2, 0.92)) if rng.random() < 0.4 else _shade(a, 0.8)
    return Material(STRIPES, a, b, scale=float(rng.uniform(3, 12)), contrast=float(rng.uniform(0.3, 1.0)),
                    axis=0, variant=1, seed=new_seed(rng))


def canvas(rng: np.random.Generator) -> Material:
    """A picture's image: blends of two random colours."""
    return Material(PAINTING, hsv(rng, (0, 1), (0.2, 0.9), (0.2, 0.95)), hsv(rng, (0, 1), (0.2, 0.9), (0.2, 0.95)),
                    scale=float(rng.uniform(2, 8)), contrast=float(rng.uniform(0.5, 1.0)), seed=new_seed(rng))


def book_row(rng: np.random.Generator) -> Material:
    """A row of book spines (random colours per spine, uneven heights) in front of a dark back."""
    return Material(BOOKS, (0.0, 0.0, 0.0), hsv(rng, (0, 1), (0.0, 0.3), (0.03, 0.12)),
                    scale=float(rng.uniform(20, 45)), contrast=1.0, axis=0, seed=new_seed(rng))


def window_glass(rng: np.random.Generator) -> Material:
    """Daylight through a window: a bright sky gradient (emissive)."""
    top = hsv(rng, (0.52, 0.62), (0.15, 0.45), (0.85, 1.0), emissive=True)
    low = hsv(rng, (0.0, 1.0), (0.0, 0.2), (0.75, 0.95), emissive=True)
    return Material(SKY, top, low, scale=1.0, contrast=float(rng.uniform(0.1, 0.3)), seed=new_seed(rng))


def lamp_glow() -> Material:
    """A ceiling light's diffuser (emissive, warm white)."""
    return Material(LAMP, (1.0, 0.95, 0.85), (1.0, 0.95, 0.85))


def dark_plastic(rng: np.random.Generator) -> Material:
    """Screens, handles and small fittings."""
    a = hsv(rng, (0, 1), (0.0, 0.1), (0.04, 0.3))
    return Material(PAINT, a, a, scale=5.0, contrast=0.05, seed=new_seed(rng))


def foliage(rng: np.random.Generator) -> Material:
    """Leaves of a potted plant: green to olive, mottled."""
    a = hsv(rng, (0.2, 0.42), (0.35, 0.85), (0.2, 0.65))
    return Material(FABRIC, a, _shade(a, 0.5), scale=float(rng.uniform(20, 40)), contrast=0.6, seed=new_seed(rng))
