"""The floor plan of a procedural room: placing pieces without collisions (floor footprints, wall spans), and room
shapes beyond the rectangle (:func:`shaped_plan`). Walls are numbered counter-clockwise seen from above: wall 0 runs
along y = 0 from x = 0 to Lx, wall 1 along x = Lx, wall 2 along y = Ly (back to x = 0), wall 3 along x = 0; a position
``s`` on a wall is measured from its start; a piece against a wall faces the room (+y inward)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sray.data_tools.synth import domains
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth.furniture import CLS, Piece, span
from sray.data_tools.synth.geometry import Box, place

Rect = tuple[float, float, float, float]
"""Axis-aligned floor rectangle (x0, x1, y0, y1) in metres."""


@dataclass
class Light:
    """A point light (not visible itself): world position in metres, brightness at 1 m in units of the ambient
    term, linear RGB tint and the colour temperature it comes from (``lighting.kelvin_rgb``)."""

    position: tuple[float, float, float]
    intensity: float
    color: tuple[float, float, float]
    kelvin: float


@dataclass
class FloorPlan:
    """A room under construction (interior extents (Lx, Ly, H) in metres): its boxes (world frame), occupied floor
    rectangles (furniture, door clearances), occupied (s0, s1, z0, z1) regions per wall, lights, (wall, s0, s1) of
    each door opening (baseboards stop there) and a point 0.6 m in front of each window (its daylight goes there)."""

    size: tuple[float, float, float]
    boxes: list[Box] = field(default_factory=list)
    footprints: list[Rect] = field(default_factory=list)
    spans: list[list[tuple[float, float, float, float]]] = field(default_factory=lambda: [[], [], [], []])
    lights: list[Light] = field(default_factory=list)
    doors: list[tuple[int, float, float]] = field(default_factory=list)
    windows: list[tuple[float, float, float]] = field(default_factory=list)

    def wall_length(self, wall: int) -> float:
        """Length of a wall in metres."""
        return self.size[0] if wall % 2 == 0 else self.size[1]

    def wall_frame(self, wall: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(start (2,), tangent (2,), inward normal (2,)) of a wall."""
        lx, ly = self.size[0], self.size[1]
        start = [(0.0, 0.0), (lx, 0.0), (lx, ly), (0.0, ly)][wall]
        tangent = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][wall]
        return np.array(start), np.array(tangent), np.array((-tangent[1], tangent[0]))

    def wall_pose(self, wall: int, s: float, depth: float, gap: float = 0.0) -> tuple[float, float, float]:
        """(x, y, yaw) of a piece of the given depth centred at ``s`` along a wall, ``gap`` off it."""
        start, tangent, normal = self.wall_frame(wall)
        centre = start + s * tangent + (gap + depth / 2) * normal
        return float(centre[0]), float(centre[1]), math.atan2(-normal[0], normal[1])

    @staticmethod
    def footprint(piece: Piece, x: float, y: float, yaw: float) -> Rect:
        """Floor rectangle covering a piece placed at (x, y) turned by yaw."""
        c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
        hx = 0.5 * (piece.width * c + piece.depth * s)
        hy = 0.5 * (piece.width * s + piece.depth * c)
        return (x - hx, x + hx, y - hy, y + hy)

    def is_free(self, rect: Rect, clearance: float = 0.05) -> bool:
        """Whether a rectangle lies inside the room and overlaps no occupied rectangle."""
        x0, x1, y0, y1 = rect
        if x0 < -1e-6 or y0 < -1e-6 or x1 > self.size[0] + 1e-6 or y1 > self.size[1] + 1e-6:
            return False
        return all(x1 + clearance <= a0 or a1 + clearance <= x0 or y1 + clearance <= b0 or b1 + clearance <= y0
                   for a0, a1, b0, b1 in self.footprints)

    def span_free(self, wall: int, s0: float, s1: float, z0: float, z1: float, gap: float = 0.05) -> bool:
        """Whether a wall region is clear of doors, windows, curtains and pieces against that wall."""
        return all(s1 + gap <= a0 or a1 + gap <= s0 or z1 <= c0 or c1 <= z0 for a0, a1, c0, c1 in self.spans[wall])

    def add(self, piece: Piece, x: float, y: float, yaw: float, occupies_floor: bool = True) -> None:
        """Put a piece in the room at (x, y) turned by yaw."""
        self.boxes.extend(place(piece.boxes, x, y, yaw))
        if occupies_floor:
            self.footprints.append(self.footprint(piece, x, y, yaw))

    def try_floor(self, piece: Piece, x: float, y: float, yaw: float, clearance: float = 0.05) -> bool:
        """Place a free-standing piece if its footprint is free; returns whether it was placed."""
        if not self.is_free(self.footprint(piece, x, y, yaw), clearance):
            return False
        self.add(piece, x, y, yaw)
        return True

    def try_wall(self, rng: np.random.Generator, piece: Piece, wall: int, z_range: tuple[float, float] | None = None,
                 s: float | None = None, gap: float = 0.015, occupies_floor: bool = True, tries: int = 25,
                 margin: float = 0.05) -> float | None:
        """Put a piece against a wall at a random (or given) ``s``: s or None; ``z_range``: its band (default 0-top)."""
        length = self.wall_length(wall)
        lo, hi = piece.width / 2 + margin, length - piece.width / 2 - margin
        if hi < lo:
            return None
        z0, z1 = z_range if z_range is not None else (0.0, piece.height)
        for _ in range(1 if s is not None else tries):
            pos = float(s) if s is not None else float(rng.uniform(lo, hi))
            if not lo - 1e-9 <= pos <= hi + 1e-9:
                return None
            s0, s1 = pos - piece.width / 2, pos + piece.width / 2
            if not self.span_free(wall, s0, s1, z0, z1):
                continue
            x, y, yaw = self.wall_pose(wall, pos, piece.depth, gap)
            if occupies_floor and not self.is_free(self.footprint(piece, x, y, yaw)):
                continue
            self.add(piece, x, y, yaw, occupies_floor)
            self.spans[wall].append((s0, s1, z0, z1))
            return pos
        return None

    def reserve_clearance(self, wall: int, s: float, width: float, depth: float) -> None:
        """Keep a floor rectangle in front of a wall position empty (door swing, walkway)."""
        start, tangent, normal = self.wall_frame(wall)
        corners = [start + a * tangent + b * normal for a in (s - width / 2, s + width / 2) for b in (0.0, depth)]
        xs, ys = [c[0] for c in corners], [c[1] for c in corners]
        self.footprints.append((min(xs), max(xs), min(ys), max(ys)))

    def add_baseboards(self, rng: np.random.Generator) -> None:
        """Skirting boards (labelled wall) along every wall, interrupted by door openings."""
        h = float(rng.uniform(0.05, 0.11))
        finish = mat.painted(rng) if rng.random() < 0.6 else mat.wood(rng)
        for wall in range(4):
            cuts = sorted((s0, s1) for w, s0, s1 in self.doors if w == wall)
            starts, ends = [0.0] + [s1 for _, s1 in cuts], [s0 for s0, _ in cuts] + [self.wall_length(wall)]
            for a, b in zip(starts, ends):
                if b - a > 0.05:
                    board = Piece([span(CLS["wall"], finish, -(b - a) / 2, (b - a) / 2, -0.006, 0.006, 0.0, h)],
                                  b - a, 0.012, h)
                    x, y, yaw = self.wall_pose(wall, (a + b) / 2, 0.012)
                    self.add(board, x, y, yaw, occupies_floor=False)


L_SHAPE_PROB = 0.3  # probability that a room loses a corner block (an L-shaped room)
COLUMN_PROB = 0.3  # probability that a room gets one wall column


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
    prev = (k - 1) % 4
    plan.spans[k].append((0.0, along, 0.0, h))  # both walls are taken over the whole height
    plan.spans[prev].append((plan.wall_length(prev) - across, plan.wall_length(prev), 0.0, h))


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
    plan.spans[wall].append((s - width / 2, s + width / 2, 0.0, plan.size[2]))


def shaped_plan(rng: np.random.Generator, size: tuple[float, float, float]) -> FloorPlan:
    """An empty floor plan of the given interior extents, sometimes L-shaped, sometimes with a column (wall-labelled
    blocks with their own finish, placed first so everything avoids them); a geometry-shifted room always loses two
    opposite corners (a Z-shaped room, which no training room is)."""
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
