"""Furniture recipes per room type, each returning (floor plan, wall finish, floor finish). Placement is rejection
sampling against the plan's free floor and wall regions; a piece that finds no room is left out."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import catalog as cat
from sray.data_tools.synth import domains
from sray.data_tools.synth import fittings as fx
from sray.data_tools.synth import furniture as fu
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth import templates as tp
from sray.data_tools.synth.floor_plan import FloorPlan, shaped_plan
from sray.data_tools.synth.room_parts import add_door, add_pictures, add_rug, add_window

Recipe = Callable[[np.random.Generator], tuple[FloorPlan, mat.Material, mat.Material]]


def _plan(rng: np.random.Generator, lx: tuple[float, float], ly: tuple[float, float], h: tuple[float, float],
          door: tuple[float, float] = (0.8, 0.95)) -> FloorPlan:
    """A plan (``shaped_plan``) with a door, sized from the ranges (floor scaled per room, held out if shifted)."""
    shifted = domains.current().geometry_shift
    scale = float(rng.uniform(*(domains.HELD_OUT_SCALE if shifted else domains.TRAIN_SCALE)))
    plan = shaped_plan(rng, (scale * float(rng.uniform(*lx)), scale * float(rng.uniform(*ly)),
                             float(rng.uniform(*(domains.HELD_OUT_CEILING if shifted else h)))))
    add_door(rng, plan, width=door)
    return plan


def _walls(rng: np.random.Generator) -> list[int]:
    return [int(w) for w in rng.permutation(4)]


def _anywhere_on_walls(rng: np.random.Generator, plan: FloorPlan, piece: fu.Piece,
                       z_range: tuple[float, float] | None = None) -> tuple[int, float] | None:
    """Try every wall in random order: (wall, s) of the placement or None (held-out wall gap when shifted)."""
    gap = float(rng.uniform(*domains.HELD_OUT_WALL_GAP)) if domains.current().geometry_shift else 0.015
    for wall in _walls(rng):
        s = plan.try_wall(rng, piece, wall, z_range=z_range, gap=gap)
        if s is not None:
            return wall, s
    return None


def _chair_facing(rng: np.random.Generator, plan: FloorPlan, x: float, y: float, yaw: float, distance: float) -> None:
    """A chair at ``distance`` from (x, y) along the direction yaw points +y to, facing back to (x, y)."""
    chair = cat.chair(rng)
    dx, dy = -math.sin(yaw), math.cos(yaw)
    cx, cy = x + dx * (distance + chair.depth / 2), y + dy * (distance + chair.depth / 2)
    plan.try_floor(chair, cx, cy, yaw + math.pi + float(rng.uniform(-0.3, 0.3)), clearance=0.02)


def _desk_with_chair(rng: np.random.Generator, plan: FloorPlan) -> None:
    desk = cat.desk(rng, float(rng.uniform(1.0, 1.6)))
    spot = _anywhere_on_walls(rng, plan, desk)
    if spot is not None:
        x, y, yaw = plan.wall_pose(spot[0], spot[1], desk.depth, 0.015)
        _chair_facing(rng, plan, x, y, yaw, desk.depth / 2 + 0.08)


def _dining_set(rng: np.random.Generator, plan: FloorPlan, chairs: int) -> None:
    """A table near the room centre with chairs around it."""
    lx, ly, _ = plan.size
    tw, td = float(rng.uniform(0.9, 1.6)), float(rng.uniform(0.7, 0.95))
    table = cat.table(rng, tw, td)
    yaw = 0.0 if rng.random() < 0.5 else math.pi / 2
    if domains.current().geometry_shift:
        yaw = float(rng.uniform(math.pi / 8, 3 * math.pi / 8))
    for _ in range(10):
        x, y = lx / 2 + float(rng.uniform(-0.5, 0.5)), ly / 2 + float(rng.uniform(-0.5, 0.5))
        if plan.try_floor(table, x, y, yaw, clearance=0.6):
            sides = [(yaw, td / 2), (yaw + math.pi, td / 2), (yaw + math.pi / 2, tw / 2), (yaw - math.pi / 2, tw / 2)]
            for side_yaw, dist in sides[:chairs]:
                _chair_facing(rng, plan, x, y, side_yaw, dist + 0.08)
            return


def bedroom(rng: np.random.Generator) -> tuple[FloorPlan, mat.Material, mat.Material]:
    """Bed with nightstands, wardrobe, desk and chair, bookshelf, ottoman or bin, pictures."""
    plan = _plan(rng, (3.4, 5.0), (3.2, 4.6), (2.45, 2.9))
    for _ in range(int(rng.integers(1, 3))):
        add_window(rng, plan)
    bw = float(rng.choice([0.9, 1.4, 1.6, 1.8]))
    bed = cat.bed(rng, bw, float(rng.uniform(1.95, 2.1)))
    for wall in _walls(rng):
        mid = plan.wall_length(wall) / 2 + float(rng.uniform(-0.4, 0.4))
        s = plan.try_wall(rng, bed, wall, s=mid)
        if s is None:
            s = plan.try_wall(rng, bed, wall)
        if s is not None:
            for side in (-1, 1):
                if rng.random() < 0.8:
                    stand = cat.cabinet(rng, float(rng.uniform(0.4, 0.55)), float(rng.uniform(0.35, 0.45)),
                                       float(rng.uniform(0.45, 0.6)))
                    plan.try_wall(rng, stand, wall, s=s + side * (bed.width / 2 + 0.06 + stand.width / 2))
            break
    _anywhere_on_walls(rng, plan, cat.cabinet(rng, float(rng.uniform(0.8, 1.6)), float(rng.uniform(0.55, 0.65)),
                                             float(rng.uniform(1.8, min(2.2, plan.size[2] - 0.2)))))
    _desk_with_chair(rng, plan)
    if rng.random() < 0.6:
        _anywhere_on_walls(rng, plan, cat.bookshelf(rng, float(rng.uniform(0.6, 1.2))))
    _anywhere_on_walls(rng, plan, fu.other_furniture(rng))
    add_pictures(rng, plan, int(rng.integers(1, 4)))
    add_rug(rng, plan, 0.5)
    return plan, mat.wall_paint(rng), mat.floor_surface(rng)


def living_room(rng: np.random.Generator) -> tuple[FloorPlan, mat.Material, mat.Material]:
    """Sofa with coffee table (on a rug) and armchairs, TV cabinet, bookshelves, side table, pictures."""
    plan = _plan(rng, (4.2, 6.5), (3.6, 5.5), (2.5, 3.0))
    for _ in range(int(rng.integers(1, 4))):
        add_window(rng, plan)
    sofa = cat.sofa(rng, float(rng.uniform(1.6, 2.4)))
    spot = _anywhere_on_walls(rng, plan, sofa)
    if spot is not None:
        x, y, yaw = plan.wall_pose(spot[0], spot[1], sofa.depth, 0.015)
        dx, dy = -math.sin(yaw), math.cos(yaw)
        ctw, ctd = float(rng.uniform(0.8, 1.2)), float(rng.uniform(0.5, 0.7))
        gap = sofa.depth / 2 + float(rng.uniform(0.35, 0.5)) + ctd / 2
        tx, ty = x + dx * gap, y + dy * gap
        if rng.random() < 0.5:
            rug = tp.rug(rng, ctw + 0.8, ctd + 1.0)
            if plan.is_free(plan.footprint(rug, tx, ty, yaw), clearance=-0.02):
                plan.add(rug, tx, ty, yaw, occupies_floor=False)
        if plan.try_floor(cat.table(rng, ctw, ctd, float(rng.uniform(0.38, 0.48))), tx, ty, yaw):
            for side in (-1, 1):
                if rng.random() < 0.6:
                    chair = fu.armchair(rng)
                    off = ctw / 2 + 0.25 + chair.depth / 2
                    ax, ay = tx + side * math.cos(yaw) * off, ty + side * math.sin(yaw) * off
                    plan.try_floor(chair, ax, ay, yaw + side * math.pi / 2 + float(rng.uniform(-0.3, 0.3)))
        side_table = cat.table(rng, 0.45, 0.45, float(rng.uniform(0.5, 0.6)))
        plan.try_wall(rng, side_table, spot[0], s=spot[1] + (sofa.width / 2 + 0.3) * float(rng.choice([-1, 1])))
    tv_stand = fu.cabinet(rng, float(rng.uniform(1.2, 1.8)), 0.42, float(rng.uniform(0.45, 0.6)))
    tv_w = float(rng.uniform(0.8, 1.3))
    tv_stand.boxes.append(fu.span(IGNORE_ID, mat.dark_plastic(rng), -tv_w / 2, tv_w / 2, -0.1, -0.04,
                                  tv_stand.height, tv_stand.height + tv_w * 0.58))
    tv_stand.height += tv_w * 0.58
    _anywhere_on_walls(rng, plan, tv_stand)
    for _ in range(int(rng.integers(1, 3))):
        _anywhere_on_walls(rng, plan, cat.bookshelf(rng, float(rng.uniform(0.6, 1.2))))
    _anywhere_on_walls(rng, plan, fu.other_furniture(rng))
    if rng.random() < 0.4:
        _desk_with_chair(rng, plan)
    add_pictures(rng, plan, int(rng.integers(2, 4)))
    return plan, mat.wall_paint(rng), mat.floor_surface(rng)


def _island(rng: np.random.Generator, plan: FloorPlan, wall: int) -> None:
    """Half the time, a kitchen island 1.0-1.3 m in front of the counter run on ``wall``, with stools (chairs)."""
    if rng.random() >= 0.5:
        return
    w, d = float(rng.uniform(1.2, 2.0)), float(rng.uniform(0.6, 0.9))
    s = plan.wall_length(wall) / 2 + float(rng.uniform(-0.3, 0.3))
    x, y, yaw = plan.wall_pose(wall, s, d, 0.62 + float(rng.uniform(1.0, 1.3)))
    if plan.try_floor(tp.kitchen_island(rng, w, d), x, y, yaw, clearance=0.5):
        for k in range(int(rng.integers(0, 3))):
            _chair_facing(rng, plan, x + (k - 0.5) * 0.5 * math.cos(yaw), y + (k - 0.5) * 0.5 * math.sin(yaw), yaw,
                          d / 2 + 0.05)


def kitchen(rng: np.random.Generator) -> tuple[FloorPlan, mat.Material, mat.Material]:
    """Counter run (base and wall cabinets, sink), fridge, maybe an island, dining set, bin, maybe a runner rug."""
    plan = _plan(rng, (3.4, 5.2), (3.0, 4.6), (2.4, 2.8))
    add_window(rng, plan, sill=(1.0, 1.15), curtain_prob=0.3)
    for wall in _walls(rng):
        length = float(rng.uniform(1.8, max(1.9, plan.wall_length(wall) - 1.2)))
        run = cat.counter_run(rng, length, float(rng.uniform(-length / 2 + 0.4, length / 2 - 0.4)))
        s = plan.try_wall(rng, run, wall, z_range=(0.0, 0.95))
        if s is None:
            continue
        fridge = cat.refrigerator(rng)
        for side in (-1, 1):
            if plan.try_wall(rng, fridge, wall, s=s + side * (length / 2 + 0.07 + fridge.width / 2)) is not None:
                break
        else:
            _anywhere_on_walls(rng, plan, fridge)
        _island(rng, plan, wall)
        z0 = float(rng.uniform(1.45, 1.6))
        z1 = min(plan.size[2] - 0.05, z0 + float(rng.uniform(0.6, 0.8)))
        for k in range(2):
            part = length / 2 - 0.05
            plan.try_wall(rng, fx.wall_cabinets(rng, part, z0, z1), wall, z_range=(z0, z1), occupies_floor=False,
                          gap=0.0, s=s - length / 2 + part / 2 + k * (part + 0.1))
        break
    _dining_set(rng, plan, int(rng.integers(2, 5)))
    if rng.random() < 0.5:
        _anywhere_on_walls(rng, plan, cat.cabinet(rng, float(rng.uniform(0.5, 0.9)), 0.55,
                                                 float(rng.uniform(1.8, min(2.1, plan.size[2] - 0.2)))))
    _anywhere_on_walls(rng, plan, fu.other_furniture(rng))
    add_pictures(rng, plan, int(rng.integers(1, 3)))
    add_rug(rng, plan, 0.3, size=(0.8, 1.6))
    return plan, mat.wall_paint(rng), mat.floor_surface(rng, wet_room=rng.random() < 0.6)


def bathroom(rng: np.random.Generator) -> tuple[FloorPlan, mat.Material, mat.Material]:
    """Bathtub with shower curtain, toilet, washbasin with mirror, cabinet, bin, small window."""
    plan = _plan(rng, (2.4, 3.4), (2.1, 3.0), (2.4, 2.7), door=(0.7, 0.82))
    add_window(rng, plan, sill=(1.2, 1.5), width=(0.5, 0.9), curtain_prob=0.2)
    for wall in sorted(range(4), key=lambda w: -plan.wall_length(w) + float(rng.uniform(0, 0.3))):
        length = min(float(rng.uniform(1.5, 1.75)), plan.wall_length(wall) - 0.05)
        tub = fx.bathtub(rng, length, float(rng.uniform(0.35, 0.8)) if rng.random() < 0.85 else None)
        end = length / 2 + 0.02 if rng.random() < 0.5 else plan.wall_length(wall) - length / 2 - 0.02
        if plan.try_wall(rng, tub, wall, s=end, margin=0.0, gap=0.005, z_range=(0.0, 0.6)) is not None:
            break
    _anywhere_on_walls(rng, plan, cat.toilet(rng))
    basin = fx.washbasin(rng, vanity=rng.random() < 0.5)
    spot = _anywhere_on_walls(rng, plan, basin)
    if spot is not None:
        plan.try_wall(rng, fx.mirror(rng, basin.width, float(rng.uniform(0.5, 0.8)), 1.55), spot[0], s=spot[1],
                      z_range=(1.1, 2.0), occupies_floor=False, gap=0.0)
    _anywhere_on_walls(rng, plan, cat.cabinet(rng, float(rng.uniform(0.35, 0.6)), float(rng.uniform(0.3, 0.4)),
                                             float(rng.uniform(0.8, 1.8))))
    _anywhere_on_walls(rng, plan, fu.other_furniture(rng))
    add_pictures(rng, plan, int(rng.integers(0, 2)))
    wall = mat.wall_paint(rng) if rng.random() < 0.5 else mat.floor_surface(rng, wet_room=True)
    return plan, wall, mat.floor_surface(rng, wet_room=True)


def office(rng: np.random.Generator) -> tuple[FloorPlan, mat.Material, mat.Material]:
    """Desks with chairs, bookshelves, file cabinets, optional meeting table and sofa, pictures."""
    plan = _plan(rng, (3.6, 6.0), (3.2, 5.0), (2.5, 3.0))
    for _ in range(int(rng.integers(1, 4))):
        add_window(rng, plan, curtain_prob=0.6)
    for _ in range(int(rng.integers(1, 4))):
        _desk_with_chair(rng, plan)
    for _ in range(int(rng.integers(1, 3))):
        _anywhere_on_walls(rng, plan, cat.bookshelf(rng, float(rng.uniform(0.6, 1.2))))
    for _ in range(int(rng.integers(1, 3))):
        _anywhere_on_walls(rng, plan, cat.cabinet(rng, float(rng.uniform(0.45, 0.9)), float(rng.uniform(0.45, 0.6)),
                                                 float(rng.uniform(0.7, 1.3))))
    if rng.random() < 0.5:
        _dining_set(rng, plan, int(rng.integers(2, 5)))
    if rng.random() < 0.35:
        _anywhere_on_walls(rng, plan, cat.sofa(rng, float(rng.uniform(1.4, 2.0))))
    if rng.random() < 0.7:
        _anywhere_on_walls(rng, plan, fu.other_furniture(rng))
    if rng.random() < 0.3:
        _anywhere_on_walls(rng, plan, tp.mini_fridge(rng))
    add_pictures(rng, plan, int(rng.integers(1, 4)))
    add_rug(rng, plan, 0.4)
    return plan, mat.wall_paint(rng), mat.floor_surface(rng)


RECIPES: dict[str, Recipe] = {"bedroom": bedroom, "living_room": living_room, "kitchen": kitchen,
                              "bathroom": bathroom, "office": office}
"""Room recipes by room type name."""
