"""`sray data synth`: determinism, round trip through the sray layout, idempotent reruns, the CLI."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from sray.data_tools.scene_folder import list_scenes, read_scene, write_scene
from sray.data_tools.synth.dataset import generate_dataset, generate_scene
from sray.jobs.data.command import register_synth


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_same_seed_gives_identical_scenes_and_another_seed_differs() -> None:
    a = generate_scene("s", 21, 5, 30, 40, "train", "living_room")
    b = generate_scene("s", 21, 5, 30, 40, "train", "living_room")
    c = generate_scene("s", 22, 5, 30, 40, "train", "living_room")
    assert a.meta.to_json() == b.meta.to_json()
    for va, vb in zip(a.views(), b.views()):
        for key in ("rgb", "depth", "label", "K", "c2w"):
            assert getattr(va, key).tobytes() == getattr(vb, key).tobytes(), key
    assert any(not np.array_equal(va.rgb, vc.rgb) for va, vc in zip(a.views(), c.views()))


def test_dataset_files_are_byte_identical_per_seed_in_one_process_or_several(tmp_path: Path) -> None:
    first = generate_dataset(tmp_path / "a", 1, 1, 20, 24, 32, seed=5, progress=False)
    generate_dataset(tmp_path / "b", 1, 1, 20, 24, 32, seed=5, progress=False, workers=2)
    assert [p.name for p in first] == ["synth_train_000", "synth_test_000"]
    files_a, files_b = _files(tmp_path / "a"), _files(tmp_path / "b")
    assert files_a.keys() == files_b.keys() and files_a == files_b
    assert len([k for k in files_a if k.endswith(".png")]) == 2 * 20 * 3
    index = json.loads((tmp_path / "a" / "dataset.json").read_text())
    assert index["scenes"] == ["synth_test_000", "synth_train_000"]
    assert [p.name for p in list_scenes(tmp_path / "a")] == index["scenes"]


def test_rerun_skips_complete_scenes_and_redoes_changed_ones(tmp_path: Path) -> None:
    generate_dataset(tmp_path, 1, 0, 6, 24, 32, seed=1, progress=False)
    meta = tmp_path / "synth_train_000" / "scene.json"
    stamp = meta.stat().st_mtime_ns
    generate_dataset(tmp_path, 1, 0, 6, 24, 32, seed=1, progress=False)
    assert meta.stat().st_mtime_ns == stamp, "an unchanged scene must be skipped"
    generate_dataset(tmp_path, 1, 0, 4, 24, 32, seed=1, progress=False)
    scene = read_scene(tmp_path / "synth_train_000")
    assert scene.meta.extra["n_views"] == 4 and len(scene.meta.view_ids) == 4
    assert sorted(p.stem for p in (tmp_path / "synth_train_000" / "rgb").glob("*.png")) == scene.meta.view_ids


def test_scene_round_trips_through_the_sray_layout(tmp_path: Path) -> None:
    scene = generate_scene("synth_rt", 8, 4, 30, 40, "train", "bathroom")
    back = read_scene(write_scene(scene, tmp_path))
    assert back.meta.to_json() == scene.meta.to_json()
    for v, w in zip(scene.views(), back.views()):
        assert np.array_equal(v.rgb, w.rgb) and np.array_equal(v.label, w.label)
        torch.testing.assert_close(torch.from_numpy(w.depth), torch.from_numpy(v.depth), rtol=0, atol=1e-3)
        torch.testing.assert_close(torch.from_numpy(w.K), torch.from_numpy(v.K), rtol=0, atol=1e-12)
        torch.testing.assert_close(torch.from_numpy(w.c2w), torch.from_numpy(v.c2w), rtol=0, atol=1e-12)


def test_cli_writes_the_dataset_and_says_where(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser(prog="sray data")
    register_synth(parser.add_subparsers(dest="verb", required=True))
    out = tmp_path / "synth"
    args = parser.parse_args(["synth", "--out", str(out), "--train-scenes", "1", "--test-scenes", "1",
                              "--views", "20", "--height", "24", "--width", "32", "--seed", "3"])
    assert args.func(args) == 0
    assert json.loads((out / "dataset.json").read_text())["scenes"] == ["synth_test_000", "synth_train_000"]
    test_meta = read_scene(out / "synth_test_000").meta
    assert test_meta.role == "test" and len(test_meta.splits["source"]) == 8
    assert str(out.resolve()) in capsys.readouterr().out
    defaults = parser.parse_args(["synth", "--out", str(out)])
    chosen = (defaults.train_scenes, defaults.test_scenes, defaults.views, defaults.height, defaults.width)
    assert chosen == (4, 2, 60, 240, 320)
