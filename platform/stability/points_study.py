"""The stability suite's points as a study of the engine (``sray.platform.sweep``): plan, stored results, run.

One trial per point key (``suite.point_key``: a spec computed once whatever the axes that ask for it), under
``<out>/study/<preset>/``, completed launch after launch (``sray.platform.sweep.incremental``): a finished
point never runs again, whatever axes a later run asks for; a point whose trial errored (its process died, say)
counts as ``failed`` in the tables until a later run that asks for it runs it again. Points stored by the
suite's earlier store (``<out>/points/<preset>/<key>.json``) are imported as finished trials, never computed
again. ``preset.json`` in the study folder records the preset definition the points were made with: a run
under a changed definition is refused (a stored point is reused only under the same levels and budgets).
"""

from __future__ import annotations

import dataclasses
import json
from functools import partial
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json
from sray.platform.stability.point_trial import SuiteInputs, spec_point, stability_point, trial_resources
from sray.platform.stability.presets import Preset
from sray.platform.stability.suite import point_key, point_record
from sray.platform.sweep.incremental import import_result, missing, run_missing
from sray.platform.sweep.outcomes import TrialOutcome
from sray.platform.sweep.study import StudySettings
from sray.platform.sweep.trial_files import ERRORED, FINISHED, read_record, trial_folder
from sray.platform.train.launcher import init_ray

STUDY_DIR = "study"
"""Folder of ``--out`` holding one study per preset name."""
OLD_POINTS_DIR = "points"
"""Folder of ``--out`` where the suite's earlier store kept one JSON file per point key, per preset name."""
PRESET_FILE = "preset.json"
"""The preset definition the points of a folder were made with."""

Planned = list[tuple[str, str, Any, int | None]]
"""(axis, method, level, seed) of points (``suite.planned_points``)."""


def study_folder(out: Path, preset: Preset) -> Path:
    """``<out>/study/<preset name>``."""
    return Path(out) / STUDY_DIR / preset.name


def check_preset_record(folder: Path, preset: Preset, write: bool = True) -> None:
    """Refuse a folder whose points were made under another definition of ``preset`` (ValueError naming the
    fix); record the definition there when it has none yet (``write``)."""
    path = Path(folder) / PRESET_FILE
    now = json.loads(json.dumps(dataclasses.asdict(preset)))
    if path.exists():
        if json.loads(path.read_text()) != now:
            raise ValueError(f"{path}: the points in {path.parent} were made with another definition of preset "
                             f"{preset.name!r}; use a new --out, or delete that folder to start again")
    elif write:
        atomic_write_json(path, now)


def study_plan(preset: Preset, planned: Planned) -> dict[str, dict[str, Any]]:
    """Point key -> the plan's point (the spec's fields), each key once, in the order of ``planned``."""
    plan: dict[str, dict[str, Any]] = {}
    for axis, method, level, seed in planned:
        key, spec, poison = point_key(preset, axis, method, level, seed)
        plan.setdefault(key, spec_point(spec, poison))
    return plan


def import_stored_points(out: Path, preset: Preset, plan: dict[str, dict[str, Any]]) -> list[str]:
    """Import the points of ``plan`` that the earlier store holds under ``out`` as finished trials (refused, as
    a resumed run, when that store was made under another preset definition); the keys imported."""
    old = Path(out) / OLD_POINTS_DIR / preset.name
    if not old.is_dir():
        return []
    check_preset_record(old, preset, write=False)
    study = study_folder(out, preset)
    return [key for key in plan if (old / f"{key}.json").is_file()
            and import_result(study, key, json.loads((old / f"{key}.json").read_text()), old / f"{key}.json")]


def run_points(out: Path, planned: Planned, inputs: SuiteInputs) -> list[TrialOutcome]:
    """Run the points of ``planned`` that have no result yet, one at a time (Ray started if needed); the
    outcome of every point key."""
    preset = inputs.preset
    study = study_folder(out, preset)
    check_preset_record(study, preset)
    plan = study_plan(preset, planned)
    imported = import_stored_points(out, preset, plan)
    if imported:
        print(f"[stability] {len(imported)} point(s) read from {Path(out) / OLD_POINTS_DIR / preset.name}",
              flush=True)
    todo = missing(study, plan)
    if todo:
        init_ray(None)
    settings = StudySettings(folder=study, metric="miou", mode="max", reuse_actors=True, label="stability",
                             trial_resources=trial_resources(inputs.device) if todo else {"CPU": 1.0})
    return run_missing(plan, partial(stability_point, inputs=inputs), settings)


def point_records(out: Path, preset: Preset, planned: Planned,
                  errors: dict[str, str] | None = None) -> list[dict[str, Any]] | None:
    """The records of the ``planned`` points from the study alone (an errored trial as a ``failed`` point with
    its error; ``errors``: key -> error of trials that died without recording one); None when any is missing."""
    study, errors = study_folder(out, preset), errors or {}
    records = []
    for axis, method, level, seed in planned:
        key, _, _ = point_key(preset, axis, method, level, seed)
        record = read_record(trial_folder(study, key))
        if record.outcome == FINISHED and record.result is not None:
            result = record.result
        elif record.outcome == ERRORED or key in errors:
            result = {"status": "failed", "miou": None, "psnr": None, "error": record.error or errors.get(key, ""),
                      "spec": key}
        else:
            return None
        records.append(point_record(axis, method, level, seed, result, key))
    return records
