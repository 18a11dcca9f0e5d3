"""A procedural room (:func:`build_room`): shell, finishes, lights, the furniture of its room type and clutter; its
interior is the box [0, Lx] x [0, Ly] x [0, H] (z up, floor at 0)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sray.data_tools.synth import materials as mat
from sray.data_tools.synth.floor_plan import Light
from sray.data_tools.synth.geometry import Box
from sray.data_tools.synth.lighting import add_lights
from sray.data_tools.synth.room_parts import add_floor_clutter
from sray.data_tools.synth.room_types import RECIPES

ROOM_TYPES: tuple[str, ...] = tuple(RECIPES)
"""Room types the generator knows."""


@dataclass
class Room:
    """A built room: extents (Lx, Ly, H) m, world boxes, point lights (the first casts shadows), ambient, finishes."""

    room_type: str
    size: tuple[float, float, float]
    boxes: list[Box]
    lights: list[Light]
    ambient: float
    wall: mat.Material
    floor: mat.Material
    ceiling: mat.Material


def build_room(rng: np.random.Generator, room_type: str) -> Room:
    """Generate a complete room of the given type from ``rng``."""
    if room_type not in RECIPES:
        raise ValueError(f"unknown room type {room_type!r}; known: {list(RECIPES)}")
    plan, wall, floor = RECIPES[room_type](rng)
    add_floor_clutter(rng, plan, int(rng.integers(0, 4)))
    add_lights(rng, plan)
    plan.add_baseboards(rng)
    return Room(room_type=room_type, size=plan.size, boxes=plan.boxes, lights=plan.lights,
                ambient=float(rng.uniform(0.12, 0.45)), wall=wall, floor=floor, ceiling=mat.ceiling_paint(rng))
