"""The world a cell of ``sray bench accuracy`` trains on: the preset's, or for a variant with its own room count
(``Variant.train_scenes``) a larger world with the same test scenes, generated once under ``OUT/worlds`` and
checked to hold exactly the preset world's test scenes, so every cell's zero-shot number scores the same rooms."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

from sray.data_tools.atomic import atomic_write_json
from sray.data_tools.shards.manifest import MANIFEST_NAME, read_manifest
from sray.data_tools.synth.world import World, evaluation_worlds, make_world
from sray.jobs.bench.accuracy_plan import VARIANT_SETTINGS, Preset
from sray.platform.eval.split_gap import split_summary
from sray.platform.eval.zero_shot import evaluate_checkpoint
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


SPLITS_DIR = "splits"
"""Sub-folder of the benchmark's output holding the preset world's evaluation splits (``OUT/splits/<name>``)."""


def split_shards(p: Preset, out: Path, rooms: int = 16) -> dict[str, Path]:
    """Shards of the preset world's evaluation splits by result name (``evaluation_worlds``: in-distribution,
    validation, appearance- and geometry-shifted test rooms, ``rooms`` each), generated on first use under
    ``out/splits/<name>`` and reused after; what ``sray eval --split`` and the study specs score."""
    return {name: make_bench_world(world, out / SPLITS_DIR / name, progress=False)
            for name, world in evaluation_worlds(p.world, rooms).items()}


def score_splits(p: Preset, checkpoint: Path, out: Path, tracking_uri: str, rooms: int = 16) -> dict:
    """Zero-shot scores of ``checkpoint`` on the preset world's evaluation splits (:func:`split_shards`), with the
    preset's evaluation protocol, side by side (``split_gap.split_summary``, in-distribution first), written to
    ``out/splits/summary.json``; each split's reports under ``out/splits/eval/<name>``."""
    reports = {name: evaluate_checkpoint(checkpoint, shards, None, out / SPLITS_DIR / "eval" / name,
                                         n_source=p.eval_sources, tracking_uri=tracking_uri, fast=p.eval_fast)
               for name, shards in split_shards(p, out, rooms).items()}
    summary = split_summary(reports)
    atomic_write_json(out / SPLITS_DIR / "summary.json", summary)
    return summary
