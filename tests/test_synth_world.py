"""``make_world``, the one procedural-world helper: it writes the same files as generating and sharding directly,
reuses a world folder on a later call (also one the direct calls made), and refuses another world or a damaged
shard naming the folder, the field and the fix."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from sray.data_tools.shards.writer import write_shards
from sray.data_tools.synth import world as world_module
from sray.data_tools.synth.dataset import generate_dataset
from sray.data_tools.synth.world import World, WorldFolderError, make_world

TINY = World(train_scenes=1, test_scenes=1, views=20, height=24, width=32, seed=3, neighbours=8)


@pytest.fixture(scope="module")
def direct(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """TINY generated and sharded by the direct calls every caller made before the helper existed."""
    root = tmp_path_factory.mktemp("direct")
    generate_dataset(root / "scenes", n_train=1, n_test=1, n_views=20, height=24, width=32, seed=3, progress=False)
    write_shards(root / "scenes", root / "shards", neighbours=8, progress=False)
    return root


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """TINY made by the helper."""
    root = tmp_path_factory.mktemp("made")
    assert make_world(TINY, root, progress=False) == root / "shards"
    return root


def _files(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` by relative path."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _mtimes(root: Path) -> dict[str, int]:
    """Modification time (ns) of every file under ``root``."""
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()}


def test_the_helper_writes_the_files_of_the_direct_calls(direct: Path, made: Path) -> None:
    helper, reference = _files(made), _files(direct)
    assert sorted(helper) == sorted(reference)
    assert "shards/manifest.json" in helper and "scenes/synth_test_000/scene.json" in helper
    assert [name for name in helper if helper[name] != reference[name]] == []


@pytest.mark.parametrize("folder", ["made", "direct"])
def test_a_second_call_reuses_the_world_without_writing(folder: str, request: pytest.FixtureRequest,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    root = request.getfixturevalue(folder)
    calls = []
    monkeypatch.setattr(world_module, "generate_dataset", lambda *a, **k: calls.append("generate"))
    monkeypatch.setattr(world_module, "write_shards", lambda *a, **k: calls.append("shard"))
    before = _mtimes(root)
    assert make_world(TINY, root, progress=False) == root / "shards"
    assert calls == [] and _mtimes(root) == before


@pytest.mark.parametrize(("change", "says"), [
    ({"views": 21}, "views 20 (asked 21)"),
    ({"train_scenes": 2}, "train_scenes 1 (asked 2)"),
    ({"height": 48, "width": 64}, "height 24 (asked 48); width 32 (asked 64)"),
    ({"neighbours": 32}, "neighbours 8 (asked 32)"),
    ({"seed": 4}, "seed: scene synth_train_000 was not generated from seed 4"),
])
def test_another_world_is_refused_with_the_folder_the_field_and_the_fix(made: Path, change: dict, says: str) -> None:
    before = _mtimes(made)
    with pytest.raises(WorldFolderError) as refused:
        make_world(replace(TINY, **change), made, progress=False)
    message = str(refused.value)
    assert str(made / "shards" / "manifest.json") in message and says in message
    assert f"Delete {made} to generate the asked world there, or choose another output folder" in message
    assert _mtimes(made) == before


def test_a_damaged_shard_is_refused_naming_it(made: Path, tmp_path: Path) -> None:
    root = tmp_path / "copy"
    shutil.copytree(made, root)
    shard = sorted((root / "shards").glob("*.tar"))[0]
    data = bytearray(shard.read_bytes())
    data[1000] ^= 0xFF
    shard.write_bytes(bytes(data))
    with pytest.raises(WorldFolderError, match="sha256") as refused:
        make_world(TINY, root, progress=False)
    assert str(shard) in str(refused.value) and f"delete {root}" in str(refused.value)
