"""Readers (ScanNet export, Replica renders) and their writers: round trips, label mapping, sorting,
dropped frames and resampling geometry against independent references."""

from __future__ import annotations

import math
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from source_writers import write_replica, write_scannet_export
from torch.testing import assert_close

from sray.data_tools.atomic import atomic_write_bytes
from sray.data_tools.label_spaces import NYU40, SCANNET20, SCANNET20_NYU40_IDS
from sray.data_tools.png import encode_png
from sray.data_tools.readers.common import numbered_files, resample_nearest, scale_intrinsics
from sray.data_tools.readers.replica import REPLICA_TO_SCANNET20, read_replica, replica_intrinsics
from sray.data_tools.readers.scannet import read_label_tsv, read_scannet
from sray.data_tools.scene import IGNORE_ID, Scene, SceneMeta, View

H, W = 24, 32


def write_tsv(path: Path) -> Path:
    """A small stand-in for scannetv2-labels.combined.tsv: columns in an unusual order, raw id
    100 + n for every NYU40 id n, a second raw id (7) for chairs, one row without nyu40id."""
    lines = ["nyu40id\traw_category\tid\tcount\tnyu40class"]
    lines += [f"{n}\tthing{n}\t{100 + n}\t1\t{NYU40[n - 1]}" for n in range(1, 41)]
    lines += ["5\tstool\t7\t3\tchair", "\tunknown\t999\t1\t"]
    path.write_text("\n".join(lines) + "\n")
    return path


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation (3, 3) with det +1."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def random_scene(seed: int, n_views: int = 5, space: str = "scannet20") -> Scene:
    """Random but valid views: 90° FoV K, rigid poses, depth in (0.3, 6) m with holes, labels with ignore."""
    rng = np.random.default_rng(seed)
    names = {"scannet20": SCANNET20, "nyu40": NYU40}[space]
    views = []
    for i in range(n_views):
        c2w = np.eye(4)
        c2w[:3, :3], c2w[:3, 3] = random_rotation(rng), rng.uniform(-3, 3, 3)
        depth = rng.uniform(0.3, 6.0, (H, W)).astype(np.float32)
        depth[rng.random((H, W)) < 0.1] = 0.0
        label = rng.integers(0, len(names), (H, W)).astype(np.uint16)
        label[rng.random((H, W)) < 0.1] = IGNORE_ID
        views.append(View(view_id=f"v{i}", rgb=rng.integers(0, 256, (H, W, 3), dtype=np.uint8), depth=depth,
                          label=label, K=replica_intrinsics((H, W)), c2w=c2w))
    meta = SceneMeta(name="fixture", label_space=space, class_names=list(names),
                     view_ids=[v.view_id for v in views], splits={})
    return Scene.in_memory(meta, views)


def procedural_scene() -> Scene:
    """The procedural generator's scene, with the Replica camera (the only one that layout holds)."""
    synth = pytest.importorskip("sray.data_tools.synth.dataset")
    scene = synth.generate_scene("proc", seed=3, n_views=4, height=H, width=W, role="train")
    views = [View(v.view_id, v.rgb, v.depth, v.label, replica_intrinsics(v.hw), v.c2w) for v in scene.views()]
    return Scene.in_memory(scene.meta, views)


def assert_same_views(a: Scene, b: Scene) -> None:
    """Same views in the same order: labels and colour exact, cameras to 1e-6, depth to 1 mm."""
    va, vb = list(a.views()), list(b.views())
    assert len(va) == len(vb)
    for x, y in zip(va, vb):
        np.testing.assert_array_equal(y.rgb, x.rgb)
        np.testing.assert_array_equal(y.label, x.label)
        assert_close(torch.from_numpy(y.K), torch.from_numpy(x.K), rtol=0, atol=1e-6)
        assert_close(torch.from_numpy(y.c2w), torch.from_numpy(x.c2w), rtol=0, atol=1e-6)
        assert_close(torch.from_numpy(y.depth), torch.from_numpy(x.depth), rtol=0, atol=1e-3)
    assert b.meta.label_space == a.meta.label_space and b.meta.class_names == a.meta.class_names


@pytest.mark.parametrize("make", [lambda: random_scene(0), lambda: random_scene(1, space="nyu40"), procedural_scene],
                         ids=["random-scannet20", "random-nyu40", "procedural"])
def test_scannet_round_trip(tmp_path: Path, make) -> None:
    scene = make()
    tsv = write_tsv(tmp_path / "labels.tsv")
    write_scannet_export(scene, tmp_path / "scan", tsv)
    back = read_scannet(tmp_path / "scan", "back", tsv=tsv, label_space=scene.meta.label_space,
                        size_hw=(H, W), frame_skip=1)
    assert_same_views(scene, back)
    assert back.meta.extra["dropped_frames"] == {}


@pytest.mark.parametrize("make", [lambda: random_scene(2), lambda: random_scene(3, space="nyu40"), procedural_scene],
                         ids=["random-scannet20", "random-nyu40", "procedural"])
def test_replica_round_trip(tmp_path: Path, make) -> None:
    scene = make()
    write_replica(scene, tmp_path / "seq")
    back = read_replica(tmp_path / "seq", "back", label_space=scene.meta.label_space, frame_skip=1)
    assert_same_views(scene, back)


def test_scannet_invalid_poses_dropped_and_reported(tmp_path: Path) -> None:
    tsv = write_tsv(tmp_path / "labels.tsv")
    write_scannet_export(random_scene(4, n_views=6), tmp_path / "scan", tsv)
    (tmp_path / "scan" / "pose" / "2.txt").write_text("-inf -inf -inf -inf\n" * 4)
    (tmp_path / "scan" / "depth" / "4.png").unlink()
    scene = read_scannet(tmp_path / "scan", "s", tsv=tsv, size_hw=(H, W), frame_skip=1)
    assert scene.meta.view_ids == ["000000", "000001", "000003", "000005"]
    assert set(scene.meta.extra["dropped_frames"]) == {"2", "4"}
    assert "invalid pose" in scene.meta.extra["dropped_frames"]["2"]
    assert "depth" in scene.meta.extra["dropped_frames"]["4"]
    skipped = read_scannet(tmp_path / "scan", "s", tsv=tsv, size_hw=(H, W), frame_skip=2)
    assert skipped.meta.view_ids == ["000000", "000003"]


def test_natural_sort_of_frames(tmp_path: Path) -> None:
    scene = random_scene(5, n_views=12)
    write_replica(scene, tmp_path / "seq")
    for name in ("rgb_100.png", "rgb_x.png", "vis_rgb_3.png"):  # only rgb_<number>.png frames count
        (tmp_path / "seq" / "rgb" / name).touch()
    found = numbered_files(tmp_path / "seq" / "rgb", r"rgb_(\d+)", (".png",))
    assert [p.name for p in found.values()] == [f"rgb_{i}.png" for i in [*range(12), 100]]
    (tmp_path / "seq" / "rgb" / "rgb_100.png").unlink()
    back = read_replica(tmp_path / "seq", "back", frame_skip=1)
    assert back.meta.view_ids == [f"{i:06d}" for i in range(12)]
    traj = np.loadtxt(tmp_path / "seq" / "traj_w_c.txt")
    np.testing.assert_array_equal(back.read_view("000010").c2w, traj[10].reshape(4, 4))
    np.testing.assert_array_equal(back.read_view("000010").rgb, scene.read_view("v10").rgb)


def test_tsv_mapping_and_unmapped_ids(tmp_path: Path) -> None:
    tsv = write_tsv(tmp_path / "labels.tsv")
    scene = random_scene(6, n_views=1)
    write_scannet_export(scene, tmp_path / "scan", tsv)
    raw = np.tile(np.array([[0, 7, 105, 113], [999, 4242, 140, 139]], np.uint16), (H // 2, W // 4))
    atomic_write_bytes(tmp_path / "scan" / "label-filt" / "0.png", encode_png(raw))
    got20 = read_scannet(tmp_path / "scan", "s", tsv=tsv, size_hw=(H, W), frame_skip=1).read_view("000000").label
    got40 = read_scannet(tmp_path / "scan", "s", tsv=tsv, label_space="nyu40", size_hw=(H, W),
                         frame_skip=1).read_view("000000").label
    # raw 0: unannotated; 7 and 105: chair; 113 (nyu40 13 blinds) is not a ScanNet-20 class;
    # 999: no nyu40id; 4242: not in the tsv; 140: otherprop (not ScanNet-20); 139: otherfurniture.
    i = IGNORE_ID
    expect20 = {0: i, 7: 4, 105: 4, 113: i, 999: i, 4242: i, 140: i, 139: 19}
    expect40 = {0: i, 7: 4, 105: 4, 113: 12, 999: i, 4242: i, 140: 39, 139: 38}
    np.testing.assert_array_equal(got20, np.vectorize(expect20.get)(raw))
    np.testing.assert_array_equal(got40, np.vectorize(expect40.get)(raw))
    assert read_label_tsv(tsv)[7] == 5 and SCANNET20_NYU40_IDS[4] == 5


@pytest.mark.parametrize("missing", ["id", "nyu40id"])
def test_tsv_missing_column_is_a_clear_error(tmp_path: Path, missing: str) -> None:
    tsv = tmp_path / "bad.tsv"
    header = [c for c in ("id", "raw_category", "nyu40id") if c != missing]
    tsv.write_text("\t".join(header) + "\n" + "\t".join("1" for _ in header) + "\n")
    with pytest.raises(ValueError, match=rf"bad\.tsv.*column '{missing}' is missing"):
        read_label_tsv(tsv)


def test_replica_missing_class_table_names_the_fix(tmp_path: Path) -> None:
    write_replica(random_scene(7, n_views=2), tmp_path / "room" / "seq")
    (tmp_path / "room" / "seq" / "info_semantic.json").unlink()
    with pytest.raises(FileNotFoundError, match=r"info_semantic\.json.*--classes"):
        read_replica(tmp_path / "room" / "seq", "s")


def test_replica_class_names_map_through_nyu40(tmp_path: Path) -> None:
    assert REPLICA_TO_SCANNET20["base cabinet"] == "cabinet" and REPLICA_TO_SCANNET20["ceiling"] is None
    assert REPLICA_TO_SCANNET20["countertop"] == "counter" and REPLICA_TO_SCANNET20["rug"] is None
    scene = random_scene(8, n_views=1)
    write_replica(scene, tmp_path / "seq")
    table = '{"classes": [{"id": 1, "name": "base-cabinet"}, {"id": 2, "name": "Ceiling"}, {"id": 3, "name": "wall"}]}'
    (tmp_path / "seq" / "info_semantic.json").write_text(table)
    sem = np.tile(np.array([[0, 1, 2, 3]], np.uint8), (H, W // 4))
    atomic_write_bytes(tmp_path / "seq" / "semantic_class" / "semantic_class_0.png", encode_png(sem))
    view = read_replica(tmp_path / "seq", "s", frame_skip=1).read_view("000000")
    np.testing.assert_array_equal(view.label, np.tile(np.array([[IGNORE_ID, 2, IGNORE_ID, 0]]), (H, W // 4)))
    sem[0, 0] = 9
    atomic_write_bytes(tmp_path / "seq" / "semantic_class" / "semantic_class_0.png", encode_png(sem))
    with pytest.raises(ValueError, match=r"class ids \[9\] are not listed"):
        read_replica(tmp_path / "seq", "s", frame_skip=1).read_view("000000")


def test_replica_intrinsics_have_a_90_degree_fov() -> None:
    K = replica_intrinsics((480, 640))
    np.testing.assert_array_equal(K, [[320, 0, 319.5], [0, 320, 239.5], [0, 0, 1]])
    left, right = (-0.5 - K[0, 2]) / K[0, 0], (639.5 - K[0, 2]) / K[0, 0]  # outer pixel edges
    assert math.degrees(math.atan(right) - math.atan(left)) == pytest.approx(90.0, abs=1e-9)


@pytest.mark.parametrize("dst_hw", [(24, 32), (12, 16), (96, 128)])
def test_scaled_resampling_matches_opencv_nearest_exact(dst_hw: tuple[int, int]) -> None:
    img = np.random.default_rng(9).integers(0, 65535, (48, 64)).astype(np.uint16)
    K = np.array([[50.0, 0, 31.5], [0, 47.0, 23.5], [0, 0, 1]])
    got = resample_nearest(img, K, scale_intrinsics(K, (48, 64), dst_hw), dst_hw, 0)
    np.testing.assert_array_equal(got, cv2.resize(img, dst_hw[::-1], interpolation=cv2.INTER_NEAREST_EXACT))


def test_scaled_intrinsics_follow_the_pixel_centre_rule() -> None:
    """Exact rational reference: target pixel u samples source floor((u + 1/2) * W_src / W_dst)."""
    K = np.array([[50.0, 0, 31.5], [0, 47.0, 23.5], [0, 0, 1]])
    img = np.arange(48 * 64, dtype=np.int32).reshape(48, 64)
    for dst_hw in [(30, 40), (17, 23), (61, 83)]:
        got = resample_nearest(img, K, scale_intrinsics(K, (48, 64), dst_hw), dst_hw, -1)
        rows = [math.floor((Fraction(v) + Fraction(1, 2)) * Fraction(48, dst_hw[0])) for v in range(dst_hw[0])]
        cols = [math.floor((Fraction(u) + Fraction(1, 2)) * Fraction(64, dst_hw[1])) for u in range(dst_hw[1])]
        np.testing.assert_array_equal(got, img[np.ix_(rows, cols)])


def test_scannet_depth_resampled_into_the_colour_camera(tmp_path: Path) -> None:
    """Colour 128x96 and depth 64x48 with different intrinsics; the reader's 32x24 depth must equal,
    pixel by pixel, the depth of the source pixel nearest to where each target ray hits the depth image."""
    tsv = write_tsv(tmp_path / "labels.tsv")
    write_scannet_export(random_scene(10, n_views=1), tmp_path / "scan", tsv)
    scan = tmp_path / "scan"
    Kc = np.array([[110.0, 0, 63.0], [0, 108.0, 48.5], [0, 0, 1]])
    Kd = np.array([[58.0, 0, 32.5], [0, 57.0, 23.0], [0, 0, 1]])
    for name, K in (("intrinsic_color.txt", Kc), ("intrinsic_depth.txt", Kd)):
        K4 = np.eye(4)
        K4[:3, :3] = K
        np.savetxt(scan / "intrinsic" / name, K4)
    rng = np.random.default_rng(11)
    atomic_write_bytes(scan / "color" / "0.png", encode_png(rng.integers(0, 256, (96, 128, 3), dtype=np.uint8)))
    depth_mm = rng.integers(300, 6000, (48, 64)).astype(np.uint16)
    atomic_write_bytes(scan / "depth" / "0.png", encode_png(depth_mm))
    atomic_write_bytes(scan / "label-filt" / "0.png", encode_png(np.full((96, 128), 105, np.uint16)))
    view = read_scannet(scan, "s", tsv=tsv, size_hw=(24, 32), frame_skip=1).read_view("000000")
    Kt = Kc.copy()
    Kt[0] = [110.0 / 4, 0, (63.0 + 0.5) / 4 - 0.5]
    Kt[1] = [0, 108.0 / 4, (48.5 + 0.5) / 4 - 0.5]
    assert_close(torch.from_numpy(view.K), torch.from_numpy(Kt), rtol=0, atol=1e-12)
    expect = np.zeros((24, 32), np.float32)
    for v in range(24):
        for u in range(32):
            x, y = (u - Kt[0, 2]) / Kt[0, 0], (v - Kt[1, 2]) / Kt[1, 1]  # normalised ray of the target pixel
            col, row = math.floor(Kd[0, 0] * x + Kd[0, 2] + 0.5), math.floor(Kd[1, 1] * y + Kd[1, 2] + 0.5)
            if 0 <= col < 64 and 0 <= row < 48:
                expect[v, u] = depth_mm[row, col] / 1000.0
    assert_close(torch.from_numpy(view.depth), torch.from_numpy(expect), rtol=0, atol=1e-6)
    assert (view.label == 4).all() and view.rgb.shape == (24, 32, 3)
