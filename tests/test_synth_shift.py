"""Shifted test splits of the procedural generator: training rooms never enter the held-out regions, shifted rooms
do, a shifted room's pixels really differ per class, and a world records and checks its split."""

from __future__ import annotations

import colorsys
import math

import cv2
import numpy as np
import pytest

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import domains
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth.dataset import generate_scene, intrinsics, plan_scene, scene_seed
from sray.data_tools.synth.furniture import CLS
from sray.data_tools.synth.render import render_view
from sray.data_tools.synth.world import World, recorded_differences

EXEMPT_KINDS = (mat.SKY, mat.LAMP, mat.BOOKS)
"""Emissive kinds and hashed book spines (ignore-labelled) draw no surface colour from ``materials.hsv``."""


def _materials(plan) -> list[mat.Material]:
    room = plan.room
    return [b.material for b in room.boxes] + [room.wall, room.floor, room.ceiling]


def _hsv(linear: tuple[float, float, float]) -> tuple[float, float, float]:
    return colorsys.rgb_to_hsv(*(float(c) ** (1 / 2.2) for c in linear))


def _held_out_texture(m: mat.Material) -> bool:
    """The held-out texture region: stone anywhere, or a plaid fabric coarser than 10 cycles per metre."""
    return m.kind == mat.MARBLE or (m.kind == mat.FABRIC and m.variant == 1 and m.scale < 10.0)


def _held_out_colours(plan) -> int:
    return sum(domains.held_out_colour(h, s) for m in _materials(plan) if m.kind not in EXEMPT_KINDS
               for h, s, _ in (_hsv(m.color_a), _hsv(m.color_b)))


def _corner_blocks(plan) -> int:
    """Full-height wall-labelled boxes touching two walls (the blocks cut out of corners)."""
    lx, ly, h = plan.room.size
    count = 0
    for b in plan.room.boxes:
        lo = np.asarray(b.center) - np.asarray(b.size) / 2
        hi = np.asarray(b.center) + np.asarray(b.size) / 2
        touches = (lo[0] < 1e-6 or hi[0] > lx - 1e-6) and (lo[1] < 1e-6 or hi[1] > ly - 1e-6)
        count += b.label == CLS["wall"] and abs(b.size[2] - h) < 1e-6 and touches
    return count


@pytest.fixture(scope="module")
def training_plans() -> list:
    return [plan_scene(scene_seed(3, "train", i), 20) for i in range(24)]


def test_training_rooms_never_sample_a_held_out_region(training_plans: list) -> None:
    for plan in training_plans:
        scene, room = plan.render_scene, plan.room
        assert _held_out_colours(plan) == 0
        assert not any(_held_out_texture(m) for m in _materials(plan))
        assert min(light.kelvin for light in room.lights) >= 2400.0 and room.lights[0].position[2] >= 2.0
        assert abs(math.log2(scene.exposure)) <= domains.TRAIN_EXPOSURE_EV
        assert scene.tone == domains.TRAIN_TONE and scene.noise_sigma == 0.0
        assert room.size[2] <= 3.0 and _corner_blocks(plan) <= 1
        heights = plan.poses[:, 2, 3]
        assert heights.min() >= 1.0 - 1e-9 and heights.max() <= 1.85 + 1e-9


def test_appearance_shifted_rooms_sample_the_held_out_appearance_and_keep_training_geometry() -> None:
    for i in range(6):
        plan = plan_scene(scene_seed(3, "test", i, "appearance-shift"), 20, split="appearance-shift")
        scene, room = plan.render_scene, plan.room
        assert _held_out_colours(plan) >= 3
        ceiling = [light for light in room.lights[1:] if light.position[2] > 2.0 and light.kelvin < 2400]
        assert ceiling and all(domains.HELD_OUT_KELVIN[0] <= light.kelvin <= domains.HELD_OUT_KELVIN[1]
                               for light in ceiling)
        assert room.lights[0].position[2] <= domains.LOW_LIGHT_TOP
        assert abs(math.log2(scene.exposure)) >= domains.HELD_OUT_EXPOSURE_EV[0]
        assert scene.tone != domains.TRAIN_TONE and scene.noise_sigma >= domains.HELD_OUT_NOISE[0]
        assert room.size[2] <= 3.0 and plan.poses[:, 2, 3].min() >= 1.0 - 1e-9


def test_geometry_shifted_rooms_sample_the_held_out_geometry_and_keep_training_appearance() -> None:
    for i in range(6):
        plan = plan_scene(scene_seed(3, "test", i, "geometry-shift"), 20, split="geometry-shift")
        assert plan.room.size[2] >= domains.HELD_OUT_CEILING[0] and _corner_blocks(plan) == 2
        assert plan.poses[:, 2, 3].max() <= domains.HELD_OUT_CAMERA[1] + 1e-9
        assert _held_out_colours(plan) == 0 and plan.render_scene.noise_sigma == 0.0


def _blue_share(split: str) -> float:
    """Share of the labelled pixels (every 5th view of 4 rooms of ``split``) rendered saturated blue to violet:
    OpenCV hue 90-135 (of 180) and saturation >= 64 (of 255)."""
    hits = []
    for i in range(4):
        plan = plan_scene(scene_seed(9, "test", i, split), 20, split=split)
        for k in range(0, 20, 5):
            rgb, _, label = render_view(plan.render_scene, intrinsics(18, 24), plan.poses[k], (18, 24), view_index=k)
            hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
            blue = (hsv[..., 0] >= 90) & (hsv[..., 0] < 135) & (hsv[..., 1] >= 64)
            hits.append(blue[label != IGNORE_ID])
    return float(np.concatenate(hits).mean())


def test_a_shifted_room_looks_different() -> None:
    """Saturated blue pixels, all but absent from in-distribution test and validation rooms, are common in
    appearance-shifted rooms (their held-out colours survive lighting and tone)."""
    assert _blue_share("in-distribution") < 0.01 and _blue_share("validation") < 0.01
    assert _blue_share("appearance-shift") > 0.08


def test_split_seed_streams_are_disjoint_and_a_world_records_its_split() -> None:
    seeds = {split: {scene_seed(0, "test", i, split) for i in range(16)} for split in domains.SPLITS}
    assert len(set.union(*seeds.values()) | {scene_seed(0, "train", i) for i in range(16)}) == 16 * 5
    with pytest.raises(ValueError, match="appearance-shift"):
        World(1, 1, 20, 24, 32, split="appearance")
    with pytest.raises(ValueError, match="in-distribution"):
        generate_scene("s", 1, 20, 18, 24, "train", split="geometry-shift")


def test_a_world_folder_of_another_split_is_refused(tmp_path) -> None:
    from sray.data_tools.shards.manifest import read_manifest
    from sray.data_tools.synth.world import make_world

    world = World(0, 1, 20, 12, 16, split="geometry-shift", neighbours=4)
    manifest = read_manifest(make_world(world, tmp_path, progress=False))
    assert recorded_differences(world, manifest) == []
    other = World(0, 1, 20, 12, 16, split="appearance-shift", neighbours=4)
    assert any(p.startswith("split geometry-shift") for p in recorded_differences(other, manifest))


def test_evaluation_worlds_share_the_world_s_settings_and_hold_no_training_room() -> None:
    from sray.data_tools.synth.world import evaluation_worlds

    world = World(48, 4, 40, 120, 160, seed=2)
    worlds = evaluation_worlds(world)
    assert {w.split for w in worlds.values()} == set(domains.SPLITS)
    for w in worlds.values():
        assert (w.train_scenes, w.test_scenes, w.views, w.height, w.width, w.seed) == (0, 16, 40, 120, 160, 2)
    training = {scene_seed(2, "train", i) for i in range(48)}
    tested = {scene_seed(2, "test", i, w.split) for w in worlds.values() for i in range(16)}
    assert not training & tested and len(tested) == 64


def test_appearance_randomisation_varies_surfaces_rooms_and_views_inside_the_training_region() -> None:
    with domains.drawing(domains.Domain(randomise=1.0)):
        rng = np.random.default_rng(0)
        hues = {round(_hsv(mat.hsv(rng, (0.2, 0.2), (0.5, 0.5), (0.5, 0.5)))[0], 3) for _ in range(20)}
    assert len(hues) > 10 and all(0.09 < h < 0.31 for h in hues)  # per surface: around the box, up to ±0.1
    plans = [plan_scene(scene_seed(4, "train", i), 20, randomise=1.0) for i in range(8)]
    for plan in plans:
        assert _held_out_colours(plan) == 0 and not any(_held_out_texture(m) for m in _materials(plan))
        assert abs(math.log2(plan.render_scene.exposure)) <= domains.TRAIN_EXPOSURE_EV
    tints = {plan.render_scene.tint for plan in plans}
    assert len(tints) == 8 and all(2 ** -0.2 <= g <= 2 ** 0.2 for t in tints for g in t)  # per room
    scene, pose = plans[0].render_scene, plans[0].poses[0]
    K = intrinsics(18, 24)
    a = render_view(scene, K, pose, (18, 24), view_index=0)[0].astype(np.float64)
    b = render_view(scene, K, pose, (18, 24), view_index=1)[0].astype(np.float64)
    ok = (a > 20) & (a < 235) & (b > 20) & (b < 235)
    assert not np.array_equal(a, b) and ok.sum() > 100  # per view: same pose, another exposure
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        World(1, 1, 20, 24, 32, randomise=1.5)
    with pytest.raises(ValueError, match="training rooms"):
        plan_scene(1, 20, split="appearance-shift", randomise=0.5)
