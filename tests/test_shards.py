"""``sray data shard``: exact round trip, byte-identical re-runs, checksums, damage and interruption."""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import tarfile
from pathlib import Path

import cv2
import numpy as np
import pytest
import scene_fixtures
import webdataset as wds

from sray.data_tools import atomic
from sray.data_tools.scene import source_pool
from sray.data_tools.scene_folder import list_scenes, read_scene
from sray.data_tools.shards.manifest import MANIFEST_NAME, read_manifest, verify_shards
from sray.data_tools.shards.writer import DatasetRejected, write_shards

SPECS = [("kitchen", 7, "train"), ("office", 5, "train"), ("unseen", 10, "test")]


def _files(folder: Path) -> dict[str, bytes]:
    """Every file of a folder by name, with its bytes."""
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def scenes_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two train scenes and one test scene in sray layout (40x30)."""
    return scene_fixtures.write_dataset(tmp_path_factory.mktemp("scenes"), SPECS)


@pytest.fixture(scope="module")
def shards_dir(scenes_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Those scenes sharded 3 views per shard, 6 neighbours per view."""
    out = tmp_path_factory.mktemp("shards")
    write_shards(scenes_dir, out, views_per_shard=3, neighbours=6, progress=False)
    return out


def test_round_trip_is_exact_and_grouped_by_scene(scenes_dir: Path, shards_dir: Path) -> None:
    """Every view comes back bit-exact through a plain webdataset reader; a shard holds one scene."""
    manifest = read_manifest(shards_dir)
    for scene_path in list_scenes(scenes_dir):
        scene = read_scene(scene_path)
        name = scene.meta.name
        entry = manifest.scenes[name]
        assert entry.meta == scene.meta.to_json() and entry.n_views == len(scene.meta.view_ids)
        assert all(s.startswith(f"{name}-") for s in entry.shards) and len(entry.shards) == -(-entry.n_views // 3)
        seen = []
        for shard in entry.shards:
            samples = list(wds.WebDataset(str(shards_dir / shard), shardshuffle=False))
            assert samples[0]["scene.json"] and json.loads(samples[0]["scene.json"]) == scene.meta.to_json()
            assert all("scene.json" not in s for s in samples[1:])
            for s in samples:
                scene_name, view_id = s["__key__"].split("__")
                assert scene_name == name and "." not in s["__key__"]
                view = scene.read_view(view_id)
                rgb = cv2.cvtColor(cv2.imdecode(np.frombuffer(s["rgb.png"], np.uint8), cv2.IMREAD_UNCHANGED),
                                   cv2.COLOR_BGR2RGB)
                depth_mm = cv2.imdecode(np.frombuffer(s["depth.png"], np.uint8), cv2.IMREAD_UNCHANGED)
                label = cv2.imdecode(np.frombuffer(s["label.png"], np.uint8), cv2.IMREAD_UNCHANGED)
                camera = json.loads(s["camera.json"])
                np.testing.assert_array_equal(rgb, view.rgb)
                assert depth_mm.dtype == np.uint16 and label.dtype == np.uint16
                np.testing.assert_array_equal(depth_mm.astype(np.float32) / 1000.0, view.depth)
                np.testing.assert_array_equal(label, view.label)
                np.testing.assert_array_equal(np.array(camera["K"]), view.K)
                np.testing.assert_array_equal(np.array(camera["c2w"]), view.c2w)
                assert camera["image_size"] == list(view.hw)
                neighbours = json.loads(s["neighbours.json"])
                pool = source_pool(scene.meta)
                assert view_id not in neighbours["ids"] and set(neighbours["ids"]) <= set(pool)
                assert len(neighbours["ids"]) == min(6, len(set(pool) - {view_id}))
                assert neighbours["scores"] == sorted(neighbours["scores"], reverse=True)
                seen.append(view_id)
        assert seen == scene.meta.view_ids


def test_manifest_lists_checksums_sizes_and_rules(scenes_dir: Path, shards_dir: Path) -> None:
    """Every listed shard's sha256 and size match the file; label spaces and the neighbour rule are named."""
    raw = json.loads((shards_dir / MANIFEST_NAME).read_text())
    assert raw["format"] == "sray-shards" and raw["version"] == 1
    assert raw["neighbours"]["rule"] == "frustum-overlap" and raw["neighbours"]["k"] == 6
    assert raw["neighbours"]["version"] == 2 and "never read" in raw["neighbours"]["test_views"]
    assert raw["label_spaces"] == {"scannet20": scene_fixtures.SCANNET20}
    tars = sorted(p.name for p in shards_dir.glob("*.tar"))
    assert [s["path"] for s in raw["shards"]] == tars
    for s in raw["shards"]:
        data = (shards_dir / s["path"]).read_bytes()
        assert s["sha256"] == hashlib.sha256(data).hexdigest() and s["bytes"] == len(data)
        with tarfile.open(shards_dir / s["path"]) as tar:
            assert len({m.name.split(".")[0] for m in tar.getmembers()}) == s["n_views"]
            assert {(m.mtime, m.uid, m.gid, m.uname, m.gname) for m in tar.getmembers()} == {(0, 0, 0, "", "")}
    assert verify_shards(shards_dir) == []


def test_rerun_is_idempotent_and_deterministic(scenes_dir: Path, shards_dir: Path, tmp_path: Path) -> None:
    """A re-run rewrites nothing; a fresh run elsewhere gives byte-identical shards and manifest."""
    before = _files(shards_dir)
    result = write_shards(scenes_dir, shards_dir, views_per_shard=3, neighbours=6, progress=False)
    assert result.written == [] and result.removed == [] and len(result.unchanged) == len(before) - 1
    assert _files(shards_dir) == before
    write_shards(scenes_dir, tmp_path, views_per_shard=3, neighbours=6, progress=False)
    assert _files(tmp_path) == before


def test_damage_is_detected(shards_dir: Path, tmp_path: Path) -> None:
    """Truncation fails the size check; a same-size byte flip fails only the checksum; the loader refuses both."""
    from sray.data_tools.loader.shard_loader import make_train_loader

    copy = tmp_path / "copy"
    shutil.copytree(shards_dir, copy)
    shard = copy / "kitchen-000001.tar"
    data = shard.read_bytes()
    shard.write_bytes(data[: len(data) // 2])
    problems = verify_shards(copy, checksums=False)
    assert len(problems) == 1 and "kitchen-000001.tar" in problems[0] and "truncated" in problems[0]
    with pytest.raises(ValueError, match="kitchen-000001.tar"):
        make_train_loader(copy, n_source=2, top_k=3, rays_per_batch=8, batches_per_epoch=2, rank=0,
                          world_size=1, num_workers=0, seed=0)
    flipped = bytearray(data)
    flipped[len(data) // 3] ^= 0xFF
    shard.write_bytes(bytes(flipped))
    assert verify_shards(copy, checksums=False) == []
    problems = verify_shards(copy)
    assert len(problems) == 1 and "sha256" in problems[0]
    (copy / MANIFEST_NAME).unlink()
    assert "missing" in verify_shards(copy)[0]


def _interrupt_on_nth_replace(monkeypatch: pytest.MonkeyPatch, n: int) -> None:
    """Make the n-th rename of a finished temporary file raise, as a crash mid-run would."""
    real_replace, calls = os.replace, []

    def replace(src: str | Path, dst: str | Path) -> None:
        calls.append(dst)
        if len(calls) == n:
            raise KeyboardInterrupt("simulated interruption")
        real_replace(src, dst)

    monkeypatch.setattr(atomic.os, "replace", replace)


def test_interrupted_run_leaves_nothing_that_looks_complete(scenes_dir: Path, shards_dir: Path, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """No manifest, no temporary files, and every visible shard is whole; a finished re-run heals the folder."""
    out = tmp_path / "fresh"
    _interrupt_on_nth_replace(monkeypatch, 3)
    with pytest.raises(KeyboardInterrupt):
        write_shards(scenes_dir, out, views_per_shard=3, neighbours=6, progress=False)
    monkeypatch.undo()
    left = _files(out)
    assert MANIFEST_NAME not in left and not [n for n in left if n.startswith(".")]
    assert sorted(left) == ["kitchen-000000.tar", "kitchen-000001.tar"]
    reference = _files(shards_dir)
    assert all(left[n] == reference[n] for n in left)
    assert "missing" in verify_shards(out)[0]

    # Re-shard a complete folder with other settings and interrupt: the old manifest is gone first.
    redo = tmp_path / "redo"
    shutil.copytree(shards_dir, redo)
    _interrupt_on_nth_replace(monkeypatch, 2)
    with pytest.raises(KeyboardInterrupt):
        write_shards(scenes_dir, redo, views_per_shard=4, neighbours=6, progress=False)
    monkeypatch.undo()
    assert not (redo / MANIFEST_NAME).exists() and not list(redo.glob(".*"))
    result = write_shards(scenes_dir, redo, views_per_shard=4, neighbours=6, progress=False)
    assert verify_shards(redo) == [] and result.removed == ["kitchen-000002.tar", "unseen-000003.tar"]
    assert sorted(p.name for p in redo.glob("*.tar")) == [s.path for s in result.manifest.shards]


def test_input_rejected_by_check_is_not_sharded(scenes_dir: Path, tmp_path: Path) -> None:
    """A dataset that `sray data check` rejects raises with the problems listed and writes nothing."""
    bad = tmp_path / "bad"
    shutil.copytree(scenes_dir, bad)
    meta_path = bad / "office" / "scene.json"
    meta = json.loads(meta_path.read_text())
    meta["near"], meta["far"] = 3.0, 1.0
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(DatasetRejected, match="office") as info:
        write_shards(bad, tmp_path / "out", progress=False)
    assert info.value.problems and all(p.fix for p in info.value.problems)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def _shard_cli(argv: list[str]) -> int:
    """Run the ``sray data shard`` verb alone (the other verbs are other modules' business)."""
    from sray.jobs.data.command import register_shard

    parser = argparse.ArgumentParser(prog="sray data")
    register_shard(parser.add_subparsers(dest="verb", required=True))
    args = parser.parse_args(["shard", *argv])
    return args.func(args)


def test_cli_shards_and_verifies(scenes_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`sray data shard` writes a verified folder; `--verify` exits non-zero on a truncated shard."""
    out = tmp_path / "cli"
    assert _shard_cli([str(scenes_dir), "--out", str(out), "--views-per-shard", "4",
                 "--neighbours", "5", "--verify"]) == 0
    assert verify_shards(out) == [] and read_manifest(out).neighbours["k"] == 5
    shard = out / "office-000000.tar"
    shard.write_bytes(shard.read_bytes()[:1000])
    assert _shard_cli(["--verify", "--out", str(out)]) == 1
    assert _shard_cli(["--out", str(out)]) == 2
    assert "office-000000.tar" in capsys.readouterr().err
