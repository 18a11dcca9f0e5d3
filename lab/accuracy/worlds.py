"""The world a cell of ``sray lab accuracy`` trains on: the preset's, or for a variant with its own room count
(``Variant.train_scenes``) a larger world with the same test scenes, generated once under ``OUT/worlds`` and
checked to hold exactly the preset world's test scenes, so every cell's zero-shot number scores the same rooms."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

from sray.data_tools.atomic import atomic_write_json
from sray.data_tools.shards.manifest import MANIFEST_NAME, read_manifest
from sray.data_tools.synth.world import World, make_world
from sray.lab.accuracy.plan import VARIANT_SETTINGS, Preset
from sray.platform.train.cpu_clock import process_tree_cpu_seconds

WORLDS_DIR = "worlds"
"""Sub-folder of the benchmark's output holding the worlds of variants with their own room count."""

GENERATION_FILE = "generation.json"
"""File of a world folder recording the CPU seconds its generation and sharding took (``cpu_s``), summed over
the processes that rendered its scenes."""


class OtherTestScenes(ValueError):
    """A cell's world whose test scenes are not the preset world's."""


def check_same_test_scenes(base: Path, shards: Path) -> None:
    """Raise :class:`OtherTestScenes` unless the shards ``shards`` hold every test scene of ``base`` with the
    same recorded metadata (seed, room type, size, splits) and no other test scene."""
    reference, other = read_manifest(base), read_manifest(shards)
    wanted = {name: e.meta for name, e in reference.scenes.items() if e.meta.get("role") == "test"}
    found = {name: e.meta for name, e in other.scenes.items() if e.meta.get("role") == "test"}
    differ = sorted(set(wanted) ^ set(found)) or [name for name in wanted if wanted[name] != found[name]]
    if differ:
        raise OtherTestScenes(f"{shards / MANIFEST_NAME}: test scenes {', '.join(differ)} differ from those of "
                               f"{base / MANIFEST_NAME}; a room count must differ from the preset world's by a "
                               "multiple of the generator's room types to keep them (delete the folder and choose "
                               "such a count)")


def make_bench_world(world: World, root: Path, progress: bool) -> Path:
    """:func:`make_world` with one scene-rendering process per CPU this process may run on (same files)."""
    return make_world(world, root, progress=progress, workers=len(os.sched_getaffinity(0)))


def cell_shards(variant: str, p: Preset, base: Path, out: Path) -> tuple[Path, float | None]:
    """(shards, CPU seconds spent generating them) of a cell of ``variant``: the preset world's shards ``base``
    (None seconds), or :func:`rooms_shards` of the variant's own room count."""
    rooms = VARIANT_SETTINGS[variant].train_scenes
    if rooms is None or rooms == p.world.train_scenes:
        return base, None
    return rooms_shards(rooms, p, base, out)


def rooms_shards(rooms: int, p: Preset, base: Path, out: Path) -> tuple[Path, float | None]:
    """(shards, CPU seconds their generation took) of the preset world with ``rooms`` training rooms:
    ``out/worlds/train<rooms>/shards``, generated on first use by one process per CPU this process may run on
    and sharded (its CPU seconds, summed over those processes, recorded in the folder; None for a world an
    interrupted run had begun, whose whole cost no run saw), reused after;
    :class:`OtherTestScenes` unless its test scenes are those of ``base``."""
    root = out / WORLDS_DIR / f"train{rooms}"
    record = root / GENERATION_FILE
    fresh = not (root / "scenes").exists()  # generated from nothing by this call: its CPU time is the whole cost
    start = process_tree_cpu_seconds()
    shards = make_bench_world(dataclasses.replace(p.world, train_scenes=rooms), root, progress=False)
    if fresh:
        atomic_write_json(record, {"cpu_s": process_tree_cpu_seconds() - start})
    check_same_test_scenes(base, shards)
    return shards, (float(json.loads(record.read_text())["cpu_s"]) if record.exists() else None)
