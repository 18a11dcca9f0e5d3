"""The worlds of ``sray lab accuracy``'s room-count cells: a count 5 rooms (one cycle of room types) above the
preset's keeps every test scene byte for byte and shares the first training rooms; one that breaks the cycle is
refused before any training; the generation CPU time is recorded once and read back when the world is reused."""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import pytest

from sray.data_tools.shards.manifest import read_manifest
from sray.data_tools.synth.world import make_world
from sray.lab.accuracy import worlds as accuracy_worlds
from sray.lab.accuracy.plan import HOUR, ROOMS_198, Cell, Preset, World
from sray.lab.accuracy.worlds import OtherTestScenes, cell_shards, rooms_shards

TINY = Preset(world=World(train_scenes=1, test_scenes=1, views=20, height=24, width=32, neighbours=8),
              recipe="synth-cpu-hour", overrides=(), long_steps=4, ablation_steps=2, validations=1, ckpt_every=2,
              plan=(Cell(HOUR, 0),), eval_sources=2, eval_fast=None, budget_s=1.0, budgets=(1.0,),
              fleet_eval_stride=4, fleet_gpus_per_task=0.0)


def _scene_bytes(shards: Path, name: str) -> str:
    """sha256 over the shard files of scene ``name``."""
    digest = hashlib.sha256()
    for shard in read_manifest(shards).scenes[name].shards:
        digest.update((shards / shard).read_bytes())
    return digest.hexdigest()


def test_more_rooms_keep_the_test_scenes_and_a_broken_cycle_is_refused(tmp_path: Path, monkeypatch) -> None:
    base = make_world(TINY.world, tmp_path / "base", progress=False)
    shards, cpu_s = rooms_shards(6, TINY, base, tmp_path)
    assert shards == tmp_path / "worlds" / "train6" / "shards" and cpu_s is not None and cpu_s > 0
    roles = [e.meta["role"] for e in read_manifest(shards).scenes.values()]
    assert (roles.count("train"), roles.count("test")) == (6, 1)
    for name in ("synth_test_000", "synth_train_000"):  # the same rooms, the same files
        assert _scene_bytes(shards, name) == _scene_bytes(base, name), name

    def refuse(*args, **kwargs):
        raise AssertionError("an existing world was generated again")

    monkeypatch.setattr(accuracy_worlds, "make_world", lambda world, root, **kw: root / "shards")
    monkeypatch.setattr("sray.data_tools.synth.world.generate_dataset", refuse)
    assert rooms_shards(6, TINY, base, tmp_path) == (shards, cpu_s)  # reused, its recorded CPU time
    monkeypatch.undo()

    with pytest.raises(OtherTestScenes, match="synth_test_000.*multiple of the generator's room types"):
        rooms_shards(2, TINY, base, tmp_path)  # 1 room more: the test scene gets another room type


def test_cells_without_their_own_room_count_train_on_the_preset_world(tmp_path: Path) -> None:
    assert cell_shards(HOUR, TINY, tmp_path / "shards", tmp_path) == (tmp_path / "shards", None)
    same = dataclasses.replace(TINY, world=dataclasses.replace(TINY.world, train_scenes=198))
    assert cell_shards(ROOMS_198, same, tmp_path / "shards", tmp_path) == (tmp_path / "shards", None)
