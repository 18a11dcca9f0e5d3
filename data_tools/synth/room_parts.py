"""Parts every room gets: a door, windows with curtains, pictures on the walls, small things on the floor."""

from __future__ import annotations

import numpy as np

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import catalog as cat
from sray.data_tools.synth import fittings as fx
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth import templates as tp
from sray.data_tools.synth.floor_plan import FloorPlan
from sray.data_tools.synth.furniture import Piece, span


def add_door(rng: np.random.Generator, plan: FloorPlan, width: tuple[float, float] = (0.8, 0.95)) -> None:
    """A closed door (``catalog.door``; 1 in 8 a double door where wide fits) on a random wall, clear floor in front."""
    h = min(float(rng.uniform(2.0, 2.1)), plan.size[2] - 0.2)
    piece = (tp.double_door(rng, float(rng.uniform(1.2, 1.5)), h) if width[1] >= 0.9 and rng.random() < 0.125
             else cat.door(rng, float(rng.uniform(*width)), h))
    for wall in rng.permutation(4):
        s = plan.try_wall(rng, piece, int(wall), z_range=(0.0, plan.size[2]), gap=0.0, occupies_floor=False,
                          margin=0.12)
        if s is not None:
            plan.doors.append((int(wall), s - piece.width / 2, s + piece.width / 2))
            plan.reserve_clearance(int(wall), s, piece.width + 0.2, 0.85)
            return


def add_window(rng: np.random.Generator, plan: FloorPlan, sill: tuple[float, float] = (0.8, 1.0),
               width: tuple[float, float] = (0.8, 1.6), curtain_prob: float = 0.7) -> None:
    """A window (and, often, a pair of curtains) on a free stretch of wall, if one is found."""
    ceiling = plan.size[2]
    w, z_sill = float(rng.uniform(*width)), float(rng.uniform(*sill))
    h = min(float(rng.uniform(1.1, 1.6)), ceiling - z_sill - 0.3)
    if h < 0.4:
        return
    win = fx.window(rng, w, z_sill, h)
    panels, offsets, z_lo = [], [], z_sill - 0.05
    if rng.random() < curtain_prob:
        cloth, pw, overlap = mat.curtain_fabric(rng), float(rng.uniform(0.3, 0.55)), float(rng.uniform(0.05, 0.25))
        z0 = 0.02 if rng.random() < 0.6 else z_sill - 0.15
        z1 = min(ceiling - 0.05, z_sill + h + float(rng.uniform(0.12, 0.25)))
        for side in (-1.0, 1.0):
            panels.append(fx.curtain(rng, pw, z0, z1, cloth))
            offsets.append(side * (win.width / 2 - overlap + pw / 2))
        z_lo = min(z_lo, z0)
    total = max([win.width] + [2 * abs(off) + p.width for p, off in zip(panels, offsets)])
    for wall in [int(w) for w in rng.permutation(4)]:
        length = plan.wall_length(wall)
        if length < total + 0.3:
            continue
        for _ in range(15):
            s = float(rng.uniform(total / 2 + 0.1, length - total / 2 - 0.1))
            if not plan.span_free(wall, s - total / 2, s + total / 2, z_lo, z_sill + h + 0.1):
                continue
            placed = [(p, plan.wall_pose(wall, s + off, p.depth)) for p, off in zip(panels, offsets)]
            if z_lo < 0.5 and not all(plan.is_free(plan.footprint(p, *pose)) for p, pose in placed):
                continue
            plan.add(win, *plan.wall_pose(wall, s, win.depth), occupies_floor=False)
            for p, pose in placed:
                plan.add(p, *pose, occupies_floor=z_lo < 0.5)
            plan.spans[wall].append((s - total / 2, s + total / 2, z_lo, z_sill + h + 0.1))
            plan.windows.append((*plan.wall_pose(wall, s, 1.2)[:2], z_sill + h / 2))
            return


def add_pictures(rng: np.random.Generator, plan: FloorPlan, count: int) -> None:
    """Up to ``count`` framed pictures hung at eye height on free wall stretches."""
    for _ in range(count):
        w, h = float(rng.uniform(0.3, 1.0)), float(rng.uniform(0.25, 0.75))
        zc = min(float(rng.uniform(1.35, 1.75)), plan.size[2] - h / 2 - 0.15)
        pic = fx.picture(rng, w, h, zc)
        for wall in rng.permutation(4):
            if plan.try_wall(rng, pic, int(wall), z_range=(zc - h / 2, zc + h / 2), gap=0.0,
                             occupies_floor=False, tries=8) is not None:
                break


def add_rug(rng: np.random.Generator, plan: FloorPlan, prob: float, size: tuple[float, float] = (1.0, 2.2)) -> None:
    """With probability ``prob``, a rug (labelled floor, ``templates.rug``) on a free stretch of floor."""
    if rng.random() >= prob:
        return
    w, d = float(rng.uniform(*size)), float(rng.uniform(0.6, 0.75)) * float(rng.uniform(*size))
    piece = tp.rug(rng, w, d)
    lx, ly, _ = plan.size
    for _ in range(12):
        x, y = float(rng.uniform(w / 2, lx - w / 2)) if lx > w else lx / 2, float(rng.uniform(0, ly))
        yaw = 0.0 if rng.random() < 0.5 else np.pi / 2
        if plan.is_free(plan.footprint(piece, x, y, yaw), clearance=0.0):
            plan.add(piece, x, y, yaw, occupies_floor=False)
            return


def add_floor_clutter(rng: np.random.Generator, plan: FloorPlan, count: int) -> None:
    """Up to ``count`` boxes, baskets, bags and stacks on the floor against the walls (ignore-labelled props)."""
    for _ in range(count):
        w, d, h = float(rng.uniform(0.2, 0.55)), float(rng.uniform(0.2, 0.45)), float(rng.uniform(0.1, 0.5))
        cover = mat.fabric(rng) if rng.random() < 0.5 else mat.painted(rng)
        boxes = [span(IGNORE_ID, cover, -w / 2, w / 2, -d / 2, d / 2, 0.0, h)]
        if rng.random() < 0.4:
            top = float(rng.uniform(0.5, 0.9))
            boxes.append(span(IGNORE_ID, mat.painted(rng), -w * top / 2, w * top / 2, -d * top / 2, d * top / 2,
                              h, h + float(rng.uniform(0.05, 0.25))))
        piece = Piece(boxes, w, d, max(b.center[2] + b.size[2] / 2 for b in boxes))
        for wall in [int(k) for k in rng.permutation(4)]:
            if plan.try_wall(rng, piece, wall, gap=float(rng.uniform(0.01, 0.1)), tries=6) is not None:
                break
