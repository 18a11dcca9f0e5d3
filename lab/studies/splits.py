"""A study's evaluation rooms beyond its world's own test rooms: shifted test splits, the validation rooms and the
calibration of the fast render's confidence on them (docs/sweeps.md, "Studies"; docs/data.md, "Shifted test splits").

```yaml
splits: {rooms: 16}                         # every test split of `evaluations` on 16 rooms of its own world
validation: {split: validation, rooms: 16}  # or {seed: 1, rooms: 4}: in-distribution rooms of another seed
calibration: {stride: 4}                    # fit the fast rule's temperature on the validation rooms, per trial
evaluations: [zero_shot, zero_shot_appearance, zero_shot_geometry, held_out, validation]
```

With ``splits``, ``zero_shot`` (in-distribution), ``zero_shot_appearance`` and ``zero_shot_geometry`` are each scored
on ``rooms`` test rooms of the world's seed and sizes drawn from that split's region, with no training room
(``data_tools.synth.world.evaluation_worlds``); without it ``zero_shot`` is the world's own test rooms. The parsers
here raise :class:`~sray.lab.studies.spec.StudyError` through the ``fail`` they are given (file, field, fix).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from sray.data_tools.synth.world import SPLIT_RESULTS, World

TEST_SPLITS = ("zero_shot", "zero_shot_appearance", "zero_shot_geometry")
"""Result names of the test splits, in-distribution first (the reference every gap is measured from)."""
SHIFTED = ("zero_shot_appearance", "zero_shot_geometry")
"""The test splits drawn from regions no training room samples; they need ``splits``."""
MIN_SPLIT_ROOMS = 16
"""Fewest rooms per test split a study with ``splits`` may claim a gap on (issue 85: at least 16 each)."""

Fail = Callable[[Path, str, str, str], Exception]


def split_rooms(path: Path, raw: Any, evaluations: list[str], fail: Fail) -> int | None:
    """The rooms per test split of ``splits: {rooms: N}`` (None without the key); every shifted split listed in
    ``evaluations`` needs it."""
    if raw is None:
        shifted = [e for e in evaluations if e in SHIFTED]
        if shifted:
            raise fail(path, "splits", f"{shifted[0]} is listed in evaluations but the study names no split rooms",
                       f"add splits: {{rooms: {MIN_SPLIT_ROOMS}}}")
        return None
    if not isinstance(raw, dict) or set(raw) != {"rooms"}:
        raise fail(path, "splits", f"{raw!r} is not {{rooms: N}}", f"write splits: {{rooms: {MIN_SPLIT_ROOMS}}}")
    rooms = raw["rooms"]
    if isinstance(rooms, bool) or not isinstance(rooms, int) or rooms < MIN_SPLIT_ROOMS:
        raise fail(path, "splits.rooms", f"{rooms!r} rooms per split is too few to report a gap on",
                   f"write an integer >= {MIN_SPLIT_ROOMS}")
    return rooms


def validation_split(path: Path, raw: dict, world_seed: int, fail: Fail) -> str:
    """The region the validation rooms come from: ``validation`` (the generator's own validation stream) or
    ``in-distribution`` (then under another seed than the test world's)."""
    split = raw.get("split", "in-distribution")
    if split not in ("in-distribution", "validation"):
        raise fail(path, "validation.split", f"{split!r} is a test region", "write split: validation (or leave it "
                   "out and give another seed)")
    if split == "in-distribution" and raw.get("seed", world_seed) == world_seed:
        raise fail(path, "validation.seed", "the test world's own seed", "choose another seed: its rooms must be new "
                   "(or write split: validation)")
    return split


def calibration_stride(path: Path, raw: Any, fast: bool, fail: Fail) -> int | None:
    """The pixel stride of ``calibration: {stride: N}`` (None without the key); it needs the fast render."""
    if raw is None:
        return None
    if not isinstance(raw, dict) or set(raw) != {"stride"}:
        raise fail(path, "calibration", f"{raw!r} is not {{stride: N}}", "write calibration: {stride: 4} (every "
                   "4th pixel of the validation rooms' test views)")
    stride = raw["stride"]
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1:
        raise fail(path, "calibration.stride", f"{stride!r} is not an integer >= 1", "write e.g. 4")
    if not fast:
        raise fail(path, "calibration", "the full render has no confidence rule to calibrate",
                   "drop calibration or evaluate with render: fast")
    return stride


def split_world(world: World, split: str, rooms: int | None) -> World | None:
    """The world whose test rooms ``split`` (a test split's result name) is scored on: ``rooms`` rooms of its region
    at ``world``'s seed and sizes, no training room, no randomisation; None: ``world``'s own test rooms."""
    if rooms is None:
        return None
    return replace(world, train_scenes=0, test_scenes=rooms, split=SPLIT_RESULTS[split], randomise=0.0)
