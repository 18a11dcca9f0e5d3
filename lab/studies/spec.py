"""A study as a file: ``jobs/studies/<name>.yaml`` names the world, the base recipe, the arms as ``--set`` overrides,
the seeds, the budget and the evaluations (docs/sweeps.md, "Studies").

```yaml
study: hour-levers                 # the file's own name
description: one line: what the study asks
recipe: synth-cpu-hour             # the base recipe every arm starts from
world: {train_scenes: 48, test_scenes: 4, views: 40, height: 120, width: 160, seed: 0}
validation: {seed: 1, rooms: 4}    # the choosing rooms: the world's sizes, another seed, `rooms` unseen rooms
                                   # (or {split: validation, rooms: 16}: the generator's validation stream)
splits: {rooms: 16}                # optional: each test split on 16 rooms of its own world (lab/studies/splits.py)
calibration: {stride: 4}           # optional: the fast rule's temperature fitted on the validation rooms per trial
set: {run.workers: 1}              # overrides of every arm
baseline: recipe                   # the arm every paired difference subtracts
arms:
  recipe: {}
  ema: {optim.ema_decay: 0.998}    # an arm: its --set overrides, or the long form below
  rooms-498: {set: {}, world: {train_scenes: 498}, budget: {cpu_seconds: 3600}, removed_after: 7734061}
  randomise: {set: {}, world: {randomise: 1.0}}   # appearance randomisation of the training rooms (0-1)
seeds: [0, 1, 2]
budget: {cpu_seconds: 3600}        # and/or steps
evaluations: [zero_shot, held_out, validation]   # + zero_shot_appearance, zero_shot_geometry (splits), fleet, ceilings
select_on: validation              # the split that chooses between arms: validation or held_out, never zero_shot
```

:func:`load_study` refuses a wrong file with :class:`StudyError`: one line naming the file, the field and the fix.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sray.data_tools.synth.world import World
from sray.lab.studies.fleet_ceilings import CeilingsEval, FleetEval, parse_ceilings, parse_fleet
from sray.lab.studies.splits import SHIFTED, calibration_stride, split_rooms, split_world, validation_split
from sray.platform.config.recipes import RECIPES
from sray.platform.sweep.options import read_yaml_keys
from sray.platform.sweep.spec import SpecError

KEYS = ("study", "description", "recipe", "world", "validation", "set", "baseline", "arms", "seeds", "budget",
        "evaluations", "select_on", "eval", "held_out_rooms", "splits", "calibration", "fleet", "ceilings")
"""Keys a study file may hold."""
REQUIRED = ("study", "recipe", "world", "validation", "arms", "seeds", "budget", "evaluations")
SELECTION_SPLITS = ("validation", "held_out")
"""Splits that may choose between arms: never the test rooms (``zero_shot``) the study reports on."""
ROOM_SPLITS = ("zero_shot", *SHIFTED, "held_out", "validation")
"""Rooms a trial scores as ``sray eval`` does: the unseen test rooms, the appearance- and geometry-shifted test rooms
(with ``splits``), held-out views of its training rooms, the validation rooms."""
EVALUATIONS = (*ROOM_SPLITS, "fleet", "ceilings")  # + a per-room finetune, the ceiling rows (fleet_ceilings.py)
ARM_KEYS = ("set", "world", "budget", "removed_after", "note")
"""Keys of an arm's long form (the short form is a mapping of ``section.field: value`` overrides)."""
_NAME = re.compile(r"^[a-z0-9][a-z0-9-]*$")
_FIELD = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)+$")
_COMMIT = re.compile(r"^[0-9a-f]{7,40}$")


class StudyError(ValueError):
    """A study file is wrong; the message names the file, the field and the fix."""


@dataclass(frozen=True)
class Budget:
    """How long each trial trains: CPU seconds (summed over its ranks) and/or a step cap."""

    cpu_seconds: float | None = None
    steps: int | None = None

    def describe(self) -> str:
        """``3600 CPU s``, ``5000 steps`` or both."""
        parts = ([f"{self.cpu_seconds:g} CPU s"] if self.cpu_seconds else []) + \
                ([f"{self.steps} steps"] if self.steps else [])
        return " or ".join(parts)


@dataclass(frozen=True)
class Arm:
    """One arm: overrides of the base recipe, and what else differs from the study's defaults."""

    name: str
    sets: dict[str, Any]
    """``section.field`` -> value, applied as ``sray train --set`` applies it."""
    world: dict[str, int] = field(default_factory=dict)
    """World fields this arm changes (``train_scenes``: the same test rooms, more training rooms)."""
    budget: Budget | None = None
    """The arm's own budget (None: the study's)."""
    removed_after: str = ""
    """The last commit whose product had this arm's lever ('' while the product still has it)."""
    note: str = ""

    def overrides(self) -> list[str]:
        """The arm's ``section.field=value`` assignments, in file order."""
        return assignments(self.sets)


@dataclass(frozen=True)
class StudySpec:
    """A parsed study file."""

    path: Path
    name: str
    description: str
    recipe: str
    world: World
    sets: dict[str, Any]
    arms: dict[str, Arm]
    baseline: str
    seeds: tuple[int, ...]
    budget: Budget
    evaluations: tuple[str, ...]
    select_on: str
    validation_seed: int
    validation_rooms: int
    eval_sources: int = 8
    eval_fast: tuple[int, float] | None = (1, 0.9)
    """(pixel stride, confidence) of the fast render the evaluations use; None: the full renderer."""
    held_out_rooms: int = 8
    split_rooms: int | None = None
    """Rooms of each test split's own world (``splits.rooms``); None: ``zero_shot`` is the world's test rooms."""
    validation_split: str = "in-distribution"
    """Region of the validation rooms: ``in-distribution`` (another seed) or the generator's ``validation`` stream."""
    calibration_stride: int | None = None
    """Pixel stride of the fast rule's temperature fit on the validation rooms (None: uncalibrated, temperature 1)."""
    fleet: FleetEval | None = None
    ceilings: CeilingsEval | None = None

    @property
    def results_dir(self) -> Path:
        """``jobs/studies/results/<name>`` beside the spec file: one JSON per trial."""
        return self.path.parent / "results" / self.name

    def arm_world(self, arm: Arm) -> World:
        """The world ``arm`` trains on."""
        return dataclasses.replace(self.world, **arm.world)

    def validation_world(self) -> World:
        """The rooms choices are made on: the study world's sizes under the validation seed and region,
        ``validation_rooms`` test rooms and no training room."""
        return dataclasses.replace(self.world, seed=self.validation_seed, train_scenes=0, randomise=0.0,
                                   test_scenes=self.validation_rooms, split=self.validation_split)

    def evaluation_world(self, split: str) -> World | None:
        """The world whose test rooms the evaluation ``split`` scores (None: the arm's own world; ``held_out``
        reads its training rooms)."""
        if split == "validation":
            return self.validation_world()
        return None if split == "held_out" else split_world(self.world, split, self.split_rooms)

    def trial_keys(self) -> dict[str, tuple[str, int]]:
        """``<arm>--s<seed>`` -> (arm, seed) for every arm and seed, arms in file order."""
        return {f"{arm}--s{seed}": (arm, seed) for arm in self.arms for seed in self.seeds}


def assignments(sets: dict[str, Any]) -> list[str]:
    """``section.field=value`` for each override of ``sets`` (YAML's booleans as ``--set`` writes them)."""
    return [f"{k}={'true' if v is True else 'false' if v is False else v}" for k, v in sets.items()]


def _fail(path: Path, where: str, problem: str, fix: str) -> StudyError:
    return StudyError(f"{path}: {where}: {problem}; {fix}")


def _mapping(path: Path, where: str, value: Any, example: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise _fail(path, where, f"{value!r} is not a mapping", f"write e.g. {where}: {example}")
    return value


def _sets(path: Path, where: str, value: Any) -> dict[str, Any]:
    sets = _mapping(path, where, value, "{optim.lr: 0.001}")
    for key in sets:
        if not isinstance(key, str) or not _FIELD.match(key):
            raise _fail(path, where, f"{key!r} is not section.field", "name fields as --set does, e.g. optim.lr")
    return dict(sets)


def _count(path: Path, where: str, value: Any, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        raise _fail(path, where, f"{value!r} is not an integer >= {least}", f"write an integer, e.g. {max(least, 4)}")
    return value


def _world(path: Path, where: str, value: Any, partial: bool) -> dict[str, Any]:
    raw = _mapping(path, where, value, "{train_scenes: 48, test_scenes: 4, views: 40, height: 120, width: 160}")
    names = [f.name for f in dataclasses.fields(World)]
    unknown = sorted(set(raw) - set(names))
    if unknown:
        raise _fail(path, f"{where}.{unknown[0]}", "not a world field", f"use one of {', '.join(names)}")
    needed = [f.name for f in dataclasses.fields(World) if f.default is dataclasses.MISSING]
    absent = [] if partial else [n for n in needed if n not in raw]
    if absent:
        raise _fail(path, f"{where}.{absent[0]}", "missing", f"give every one of {', '.join(needed)}")
    if "split" in raw:
        raise _fail(path, f"{where}.split", "training rooms are always in-distribution",
                    "list the test splits in evaluations (zero_shot_appearance, ...) with splits: {rooms: 16}")
    return {k: _randomise(path, f"{where}.{k}", v) if k == "randomise" else
            _count(path, f"{where}.{k}", v, 0 if k in ("seed", "train_scenes") else 1) for k, v in raw.items()}


def _randomise(path: Path, where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1:
        raise _fail(path, where, f"{value!r} is not a strength in [0, 1]", "write e.g. 1.0 (0 = off)")
    return float(value)


def _budget(path: Path, where: str, value: Any) -> Budget:
    raw = _mapping(path, where, value, "{cpu_seconds: 3600}")
    unknown = sorted(set(raw) - {"cpu_seconds", "steps"})
    if unknown or not raw:
        raise _fail(path, where, f"{'unknown key ' + repr(unknown[0]) if unknown else 'empty'}",
                    "give cpu_seconds (CPU seconds per trial) and/or steps, e.g. {cpu_seconds: 3600}")
    seconds = raw.get("cpu_seconds")
    if seconds is not None and (isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or seconds <= 0):
        raise _fail(path, f"{where}.cpu_seconds", f"{seconds!r} is not a positive number", "write e.g. 3600")
    steps = _count(path, f"{where}.steps", raw["steps"], 1) if "steps" in raw else None
    return Budget(None if seconds is None else float(seconds), steps)


def _arm(path: Path, name: Any, value: Any) -> Arm:
    where = f"arms.{name}"
    if not isinstance(name, str) or not _NAME.match(name):
        raise _fail(path, where, "an arm name is lower-case letters, digits and dashes", "rename it, e.g. lr-2x")
    raw = _mapping(path, where, value, "{optim.lr: 0.002}")
    if not any("." in str(k) for k in raw) and raw:  # the long form
        unknown = sorted(set(raw) - set(ARM_KEYS))
        if unknown:
            raise _fail(path, f"{where}.{unknown[0]}", "not an arm key",
                        f"an arm is a mapping of --set overrides, or has keys {', '.join(ARM_KEYS)}")
        commit = str(raw.get("removed_after", ""))
        if commit and not _COMMIT.match(commit):
            raise _fail(path, f"{where}.removed_after", f"{commit!r} is not a commit", "write its hash, e.g. 7734061")
        return Arm(name, _sets(path, f"{where}.set", raw.get("set")), _world(path, f"{where}.world", raw.get("world"),
                   partial=True), _budget(path, f"{where}.budget", raw["budget"]) if "budget" in raw else None,
                   commit, str(raw.get("note", "")))
    return Arm(name, _sets(path, where, raw))


def load_study(path: Path) -> StudySpec:
    """Parse the study file ``path``; :class:`StudyError` naming the file, the field and the fix."""
    path = Path(path)
    try:
        raw = read_yaml_keys(path, "study file", KEYS)
    except SpecError as e:
        raise StudyError(str(e)) from None
    absent = [k for k in REQUIRED if k not in raw]
    if absent:
        raise _fail(path, absent[0], "missing", f"a study names {', '.join(REQUIRED)}")
    if raw["study"] != path.stem:
        raise _fail(path, "study", f"{raw['study']!r} is not the file's name", f"write study: {path.stem}")
    if raw["recipe"] not in RECIPES:
        raise _fail(path, "recipe", f"{raw['recipe']!r} is not a recipe", f"use one of {', '.join(sorted(RECIPES))}")
    arms_raw = _mapping(path, "arms", raw["arms"], "{recipe: {}, lr-2x: {optim.lr: 0.002}}")
    if not arms_raw:
        raise _fail(path, "arms", "no arm", "list at least one arm, e.g. recipe: {}")
    arms = {name: _arm(path, name, value) for name, value in arms_raw.items()}
    baseline = raw.get("baseline", next(iter(arms)))
    if baseline not in arms:
        raise _fail(path, "baseline", f"{baseline!r} is not an arm", f"name one of {', '.join(arms)}")
    seeds = raw["seeds"]
    if not isinstance(seeds, list) or not seeds or len(set(map(str, seeds))) != len(seeds):
        raise _fail(path, "seeds", f"{seeds!r} is not a list of distinct seeds", "write e.g. seeds: [0, 1, 2]")
    seeds = tuple(_count(path, "seeds", s, 0) for s in seeds)
    evaluations = raw["evaluations"]
    if not isinstance(evaluations, list) or not evaluations or any(e not in EVALUATIONS for e in evaluations):
        raise _fail(path, "evaluations", f"{evaluations!r}", f"list some of {', '.join(EVALUATIONS)}")
    validation = _mapping(path, "validation", raw.get("validation"), "{seed: 1, rooms: 4}")
    if "validation" not in evaluations or "rooms" not in validation or not (
            {"seed", "split"} & set(validation)) or set(validation) - {"seed", "rooms", "split"}:
        raise _fail(path, "validation", "choices are made on validation rooms that no result is reported on",
                    "give validation: {seed: 1, rooms: 4} (or {split: validation, rooms: 16}) and list validation "
                    "in evaluations")
    world = World(**_world(path, "world", raw["world"], partial=False))
    val_seed = _count(path, "validation.seed", validation.get("seed", world.seed), 0)
    val_split = validation_split(path, validation, world.seed, _fail)
    select_on = raw.get("select_on", "validation")
    if select_on not in SELECTION_SPLITS or select_on not in evaluations:
        raise _fail(path, "select_on", f"{select_on!r} cannot choose", "choose on validation (rooms no choice is "
                    "reported on; list it in evaluations), never on the test rooms")
    eval_raw = _mapping(path, "eval", raw.get("eval"), "{sources: 8, stride: 1, confidence: 0.9}")
    if set(eval_raw) - {"sources", "stride", "confidence", "render"}:
        raise _fail(path, f"eval.{sorted(set(eval_raw) - {'sources', 'stride', 'confidence', 'render'})[0]}",
                    "unknown key", "eval takes sources, render (fast or full), stride and confidence")
    fast = None if eval_raw.get("render") == "full" else (int(eval_raw.get("stride", 1)),
                                                           float(eval_raw.get("confidence", 0.9)))
    return StudySpec(path=path, name=raw["study"], description=str(raw.get("description", "")), recipe=raw["recipe"],
                     world=world, sets=_sets(path, "set", raw.get("set")), arms=arms, baseline=baseline, seeds=seeds,
                     budget=_budget(path, "budget", raw["budget"]), evaluations=tuple(evaluations),
                     select_on=select_on, validation_seed=val_seed, validation_split=val_split,
                     validation_rooms=_count(path, "validation.rooms", validation["rooms"], 1),
                     eval_sources=_count(path, "eval.sources", eval_raw.get("sources", 8), 1), eval_fast=fast,
                     held_out_rooms=_count(path, "held_out_rooms", raw.get("held_out_rooms", 8), 1),
                     split_rooms=split_rooms(path, raw.get("splits"), evaluations, _fail),
                     calibration_stride=calibration_stride(path, raw.get("calibration"), fast is not None, _fail),
                     fleet=parse_fleet(path, raw.get("fleet"), evaluations, _fail),
                     ceilings=parse_ceilings(path, raw.get("ceilings"), evaluations, _fail))
