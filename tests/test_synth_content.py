"""New procedural content carries the right ScanNet-20 labels: every pixel a piece adds to a render (found by
rendering the room with and without it: the depth changes) has the piece's class."""

from __future__ import annotations

import numpy as np
import pytest

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth import templates as tp
from sray.data_tools.synth.dataset import intrinsics, plan_scene, scene_seed
from sray.data_tools.synth.floor_plan import FloorPlan, Light
from sray.data_tools.synth.furniture import CLS
from sray.data_tools.synth.render import RenderScene, render_view
from sray.data_tools.synth.rooms import Room
from sray.data_tools.synth.trajectory import look_at

SIZE = (4.0, 4.0, 2.6)


def _render(pieces: list, target: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    plan = FloorPlan(SIZE)
    plan.add_baseboards(rng)
    for piece, pose in pieces:
        plan.add(piece, *pose, occupies_floor=False)
    room = Room("test", SIZE, plan.boxes, [Light((2.0, 2.0, 2.3), 2.0, (1.0, 1.0, 1.0), 6504.0)], 0.3,
                mat.wall_paint(rng), mat.floor_surface(rng), mat.ceiling_paint(rng))
    c2w = look_at(np.array([0.6, 0.6, 1.6]), np.asarray(target, float))
    return render_view(RenderScene.prepare(room), intrinsics(60, 80), c2w, (60, 80))


def _added_labels(piece, pose, target) -> np.ndarray:
    """Labels of the pixels whose depth the piece changes (its own surfaces; shadows change colour only), rendered
    with and without it."""
    _, depth0, _ = _render([], target)
    _, depth1, label1 = _render([(piece, pose)], target)
    changed = np.abs(depth1 - depth0) > 1e-4
    assert changed.sum() > 50, "the piece must be in view"
    return label1[changed]


def test_a_rug_s_pixels_are_floor() -> None:
    labels = _added_labels(tp.rug(np.random.default_rng(1), 1.6, 1.1), (2.2, 2.2, 0.0), (2.2, 2.2, 0.0))
    assert set(labels.tolist()) == {CLS["floor"]}


@pytest.mark.parametrize(("build", "allowed", "required"), [
    (lambda rng: tp.mini_fridge(rng), {CLS["refrigerator"]}, {CLS["refrigerator"]}),
    (lambda rng: tp.kitchen_island(rng, 1.6, 0.8), {CLS["cabinet"], CLS["counter"]}, {CLS["cabinet"], CLS["counter"]}),
    (lambda rng: tp.open_shelf(rng, 1.0), {CLS["bookshelf"], IGNORE_ID}, {CLS["bookshelf"]}),
])
def test_kitchen_pieces_and_shelves_carry_their_classes(build, allowed, required) -> None:
    labels = set(_added_labels(build(np.random.default_rng(2)), (2.5, 2.6, -0.6), (2.5, 2.6, 0.5)).tolist())
    assert required <= labels <= allowed


@pytest.mark.parametrize("build", [tp.glazed_door, tp.double_door, tp.plank_door])
def test_every_door_style_is_door(build) -> None:
    door = build(np.random.default_rng(3), 1.2 if build is tp.double_door else 0.85, 2.05)
    pose = (2.0, SIZE[1] - door.depth / 2, np.pi)  # against the far wall (y = Ly), facing the room
    assert set(_added_labels(door, pose, (2.0, SIZE[1], 1.0)).tolist()) == {CLS["door"]}


def test_generated_rooms_hold_the_new_content() -> None:
    boxes = [b for i in range(12) for b in plan_scene(scene_seed(0, "train", i), 20).room.boxes]
    labels = [b.label for b in boxes]
    rugs = [b for b in boxes if b.label == CLS["floor"]]
    assert rugs and all(b.size[2] <= 0.015 + 1e-9 and b.center[2] - b.size[2] / 2 == pytest.approx(0.0) for b in rugs)
    assert CLS["refrigerator"] in labels and CLS["counter"] in labels
