"""``sray data convert``: splits per role, bounds, atomic publication, dropped-frame reports."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from source_writers import write_replica, write_scannet_export

from sray.data_tools.check.scenes import check_dataset
from sray.data_tools.label_spaces import NYU40, SCANNET20
from sray.data_tools.readers.convert import ConvertConfig, convert_scene
from sray.data_tools.readers.replica import replica_intrinsics
from sray.data_tools.scene import IGNORE_ID, Scene, SceneMeta, View
from sray.data_tools.scene_folder import read_scene
from sray.data_tools.splits import protocol_splits, train_splits
from sray.jobs.data import convert as data_convert_cmd

H, W = 24, 32


def plane_scene(n_views: int, seed: int = 0) -> Scene:
    """Views of a fronto-parallel wall 2 m away (depth 2 m) from cameras along a line, random pixels."""
    rng = np.random.default_rng(seed)
    views = []
    for i in range(n_views):
        c2w = np.eye(4)
        c2w[0, 3] = 0.05 * i
        label = rng.integers(0, 20, (H, W)).astype(np.uint16)
        label[0] = IGNORE_ID
        views.append(View(f"v{i}", rng.integers(0, 256, (H, W, 3), dtype=np.uint8),
                          np.full((H, W), 2.0, np.float32), label, replica_intrinsics((H, W)), c2w))
    meta = SceneMeta("src", "scannet20", list(SCANNET20), [v.view_id for v in views], {})
    return Scene.in_memory(meta, views)


def write_tsv(path: Path) -> Path:
    """A minimal label tsv: raw id 100 + n -> NYU40 id n."""
    path.write_text("id\tnyu40id\n" + "".join(f"{100 + n}\t{n}\n" for n in range(1, len(NYU40) + 1)))
    return path


def replica_source(tmp_path: Path, n_views: int) -> Path:
    """A Replica-layout sequence at tmp/room_0/Sequence_1 holding ``plane_scene(n_views)``."""
    src = tmp_path / "room_0" / "Sequence_1"
    write_replica(plane_scene(n_views), src)
    return src


def test_train_role_splits_bounds_and_index(tmp_path: Path) -> None:
    src = replica_source(tmp_path, 25)
    report = convert_scene(ConvertConfig(format="replica", src=src, out=tmp_path / "ds", frame_skip=1))
    assert report.scene_dir == tmp_path / "ds" / "room_0_Sequence_1" and report.n_views == 25
    scene = read_scene(report.scene_dir)
    assert scene.meta.splits == train_splits(scene.meta.view_ids, 20)
    assert scene.meta.splits["test"] == ["000010"] and len(scene.meta.splits["train"]) == 24
    assert train_splits(["a", "b", "c", "d"], 2) == {"train": ["a", "c"], "test": ["b", "d"]}
    assert scene.meta.near == pytest.approx(2.0 * 0.9) and scene.meta.far == pytest.approx(2.0 * 1.1)
    assert json.loads((tmp_path / "ds" / "dataset.json").read_text())["scenes"] == ["room_0_Sequence_1"]
    assert check_dataset(tmp_path / "ds") == []
    assert sorted(p.name for p in (tmp_path / "ds").iterdir()) == ["dataset.json", "room_0_Sequence_1"]


def test_test_role_is_the_20_view_protocol(tmp_path: Path) -> None:
    ids = [f"{i:06d}" for i in range(24)]
    window, splits = protocol_splits(ids, None)
    assert window == ids[2:22]
    assert [len(splits[k]) for k in ("source", "finetune", "test")] == [8, 8, 4]
    assert sorted(sum(splits.values(), [])) == window
    assert splits["test"] == [window[i] for i in (2, 7, 12, 17)]
    assert splits["source"] == [window[i] for i in (1, 3, 6, 8, 11, 13, 16, 18)]
    with pytest.raises(ValueError, match="needs 20 views"):
        protocol_splits(ids[:19], None)
    src = replica_source(tmp_path, 24)
    report = convert_scene(ConvertConfig(format="replica", src=src, out=tmp_path / "ds", name="t", role="test",
                                         frame_skip=1, window_start=4))
    meta = read_scene(report.scene_dir).meta
    assert meta.role == "test" and meta.view_ids == ids[4:24]
    assert sorted(p.stem for p in (report.scene_dir / "rgb").iterdir()) == ids[4:24]
    assert check_dataset(tmp_path / "ds") == []


def test_failed_conversion_leaves_nothing(tmp_path: Path) -> None:
    src = replica_source(tmp_path, 6)
    (src / "depth" / "depth_3.png").write_bytes(b"not a png")
    out = tmp_path / "ds"
    out.mkdir()
    with pytest.raises(ValueError, match="depth_3.png: not a readable image"):
        convert_scene(ConvertConfig(format="replica", src=src, out=out, frame_skip=1))
    assert list(out.iterdir()) == []


def test_existing_scene_needs_overwrite(tmp_path: Path) -> None:
    src = replica_source(tmp_path, 8)
    cfg = ConvertConfig(format="replica", src=src, out=tmp_path / "ds", name="s", frame_skip=1, holdout_every=0)
    convert_scene(cfg)
    with pytest.raises(FileExistsError, match="--overwrite"):
        convert_scene(cfg)
    cfg.frame_skip, cfg.overwrite = 2, True
    assert convert_scene(cfg).n_views == 4
    assert sorted(p.name for p in (tmp_path / "ds").iterdir()) == ["dataset.json", "s"]
    assert read_scene(tmp_path / "ds" / "s").meta.view_ids == ["000000", "000002", "000004", "000006"]


def test_cli_reports_dropped_frames(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    tsv = write_tsv(tmp_path / "labels.tsv")
    scan = tmp_path / "scene0000_00"
    write_scannet_export(plane_scene(8), scan, tsv)
    (scan / "pose" / "6.txt").write_text("-inf -inf -inf -inf\n" * 4)
    parser = argparse.ArgumentParser()
    data_convert_cmd.register(parser.add_subparsers())
    args = parser.parse_args(["convert", str(scan), "--format", "scannet", "--out", str(tmp_path / "ds"),
                              "--tsv", str(tsv), "--size", "32x24", "--frame-skip", "1"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "7 views" in out and "frame 6: invalid pose" in out
    meta = read_scene(tmp_path / "ds" / "scene0000_00").meta
    assert meta.extra["dropped_frames"] == {"6": "invalid pose in 6.txt (-inf or NaN entries)"}
    args = parser.parse_args(["convert", str(scan), "--format", "scannet", "--out", str(tmp_path / "ds2"),
                              "--tsv", str(tmp_path / "missing.tsv")])
    assert args.func(args) == 1
    assert "missing.tsv: missing" in capsys.readouterr().err
    assert not (tmp_path / "ds2").exists() or list((tmp_path / "ds2").iterdir()) == []


def test_jpg_colour_is_read_like_opencv_reads_it(tmp_path: Path) -> None:
    tsv = write_tsv(tmp_path / "labels.tsv")
    scan = tmp_path / "scan"
    write_scannet_export(plane_scene(4), scan, tsv)
    (scan / "color" / "1.png").unlink()
    cv2.imwrite(str(scan / "color" / "1.jpg"), cv2.cvtColor(plane_scene(4).read_view("v1").rgb, cv2.COLOR_RGB2BGR))
    report = convert_scene(ConvertConfig(format="scannet", src=scan, out=tmp_path / "ds", options={"tsv": tsv},
                                         size_hw=(H, W), frame_skip=1, holdout_every=0))
    view = read_scene(report.scene_dir).read_view("000001")
    np.testing.assert_array_equal(view.rgb, cv2.imread(str(scan / "color" / "1.jpg"))[..., ::-1])
