"""Room shapes beyond the rectangle: L-shaped rooms (a floor-to-ceiling block cut out of a corner) and wall columns,
labelled wall as ScanNet labels such structure, each with its own finish; placed first, so everything avoids them.
"""

from __future__ import annotations

import numpy as np

from sray.data_tools.synth import domains
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth.floor_plan import FloorPlan
from sray.data_tools.synth.furniture import CLS, Piece, span

L_SHAPE_PROB = 0.3  # probability that a room loses a corner block (an L-shaped room)
COLUMN_PROB = 0.3  # probability that a room gets one wall column


def _reserve(plan: FloorPlan, wall: int, s0: float, s1: float, height: float) -> None:
    """Mark [s0, s1] of ``wall`` as taken over the whole height."""
    plan.spans[wall].append((s0, s1, 0.0, height))


def _solid(rng: np.random.Generator, plan: FloorPlan, rect: tuple[float, float, float, float]) -> None:
    """A floor-to-ceiling wall block over the floor rectangle ``rect`` (x0, x1, y0, y1)."""
    x0, x1, y0, y1 = rect
    h = plan.size[2]
    block = Piece([span(CLS["wall"], mat.wall_paint(rng), -(x1 - x0) / 2, (x1 - x0) / 2, -(y1 - y0) / 2,
                        (y1 - y0) / 2, 0.0, h)], x1 - x0, y1 - y0, h)
    plan.add(block, (x0 + x1) / 2, (y0 + y1) / 2, 0.0)


def add_corner_block(rng: np.random.Generator, plan: FloorPlan, corner: int | None = None) -> None:
    """Cut a block out of a corner (random unless given): the room becomes L-shaped."""
    lx, ly, h = plan.size
    k = int(rng.integers(4)) if corner is None else corner  # corner k is where wall k starts and wall k-1 ends
    start, tangent, normal = plan.wall_frame(k)
    along = float(rng.uniform(0.5, 0.3 * plan.wall_length(k)))
    across = float(rng.uniform(0.5, 0.3 * plan.wall_length((k - 1) % 4)))
    corners = [start + a * tangent + b * normal for a in (0.0, along) for b in (0.0, across)]
    xs, ys = [c[0] for c in corners], [c[1] for c in corners]
    _solid(rng, plan, (min(xs), max(xs), min(ys), max(ys)))
    _reserve(plan, k, 0.0, along, h)
    prev = (k - 1) % 4
    _reserve(plan, prev, plan.wall_length(prev) - across, plan.wall_length(prev), h)


def add_column(rng: np.random.Generator, plan: FloorPlan) -> None:
    """A square column standing against a random wall, away from the corners."""
    wall = int(rng.integers(4))
    width, depth = float(rng.uniform(0.25, 0.5)), float(rng.uniform(0.15, 0.45))
    length = plan.wall_length(wall)
    s = float(rng.uniform(0.6 + width / 2, length - 0.6 - width / 2))
    if not plan.span_free(wall, s - width / 2, s + width / 2, 0.0, plan.size[2]):
        return
    x, y, _ = plan.wall_pose(wall, s, depth)
    start, tangent, normal = plan.wall_frame(wall)
    hx = abs(tangent[0]) * width / 2 + abs(normal[0]) * depth / 2
    hy = abs(tangent[1]) * width / 2 + abs(normal[1]) * depth / 2
    _solid(rng, plan, (x - hx, x + hx, y - hy, y + hy))
    _reserve(plan, wall, s - width / 2, s + width / 2, plan.size[2])


def shaped_plan(rng: np.random.Generator, size: tuple[float, float, float]) -> FloorPlan:
    """An empty floor plan of the given interior extents, sometimes L-shaped, sometimes with a column; a
    geometry-shifted room always loses two opposite corners (a Z-shaped room, which no training room is)."""
    plan = FloorPlan(size)
    if domains.current().geometry_shift:
        first = int(rng.integers(4))
        add_corner_block(rng, plan, first)
        add_corner_block(rng, plan, (first + 2) % 4)
    elif rng.random() < L_SHAPE_PROB:
        add_corner_block(rng, plan)
    if rng.random() < COLUMN_PROB:
        add_column(rng, plan)
    return plan
