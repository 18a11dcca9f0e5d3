"""The stability suite's points as a study of the engine (``sray.platform.sweep``): plan, stored results, run.

One trial per point key (``suite.point_key``: a spec computed once whatever the axes that ask for it), under
``<out>/study/<preset>/``, completed launch after launch (``sray.platform.sweep.incremental``): a finished
point never runs again, whatever axes or rows a later run asks for; a point whose trial errored (its process died,
say) counts as ``failed`` in the tables until a later run that asks for it runs it again. ``definition.json`` in the
study folder records the preset definition and the models the points were made with: a run under a changed
definition, or with another model in a role both runs name, is refused (a stored point is reused only for the
same levels, budgets and models).
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
from sray.platform.stability.rows import SuiteModels
from sray.platform.stability.suite import Planned, point_key, point_record
from sray.platform.sweep.incremental import missing, run_missing
from sray.platform.sweep.outcomes import TrialOutcome
from sray.platform.sweep.study import StudySettings
from sray.platform.sweep.trial_files import ERRORED, FINISHED, read_record, trial_folder
from sray.platform.train.launcher import init_ray

STUDY_DIR = "study"
"""Folder of ``--out`` holding one study per preset name."""
DEFINITION_FILE = "definition.json"
"""The preset definition and the models the points of a study folder were made with."""


def study_folder(out: Path, preset: Preset) -> Path:
    """``<out>/study/<preset name>``."""
    return Path(out) / STUDY_DIR / preset.name


def check_definition(folder: Path, preset: Preset, models: SuiteModels) -> None:
    """Refuse a folder whose points were made under another definition of ``preset``, or from another model in a
    role both runs name (ValueError naming the fix); record the definition, and each model role when first given."""
    path = Path(folder) / DEFINITION_FILE
    now = json.loads(json.dumps(dataclasses.asdict(preset)))
    given = {role: str(value) for role, value in dataclasses.asdict(models).items() if value is not None}
    record = json.loads(path.read_text()) if path.exists() else {"preset": now, "models": {}}
    if record["preset"] != now:
        raise ValueError(f"{path}: the points in {path.parent} were made with another definition of preset "
                         f"{preset.name!r}; use a new --out, or delete that folder to start again")
    changed = sorted(role for role, value in given.items() if record["models"].get(role, value) != value)
    if changed:
        raise ValueError(f"{path}: the points in {path.parent} were made with other models as {changed} "
                         f"({ {r: record['models'][r] for r in changed} }); use a new --out for these models")
    if not path.exists() or given.keys() - record["models"].keys():
        atomic_write_json(path, {"preset": now, "models": {**record["models"], **given}})


def study_plan(preset: Preset, planned: Planned) -> dict[str, dict[str, Any]]:
    """Point key -> the plan's point (the spec's fields), each key once, in the order of ``planned``."""
    plan: dict[str, dict[str, Any]] = {}
    for axis, row, level, seed in planned:
        key, spec, poison = point_key(preset, axis, row, level, seed)
        plan.setdefault(key, spec_point(spec, poison))
    return plan


def run_points(out: Path, planned: Planned, inputs: SuiteInputs) -> list[TrialOutcome]:
    """Run the points of ``planned`` that have no result yet, one at a time (Ray started if needed); the
    outcome of every point key."""
    preset = inputs.preset
    study = study_folder(out, preset)
    check_definition(study, preset, inputs.models)
    plan = study_plan(preset, planned)
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
    for axis, row, level, seed in planned:
        key, _, _ = point_key(preset, axis, row, level, seed)
        record = read_record(trial_folder(study, key))
        if record.outcome == FINISHED and record.result is not None:
            result = record.result
        elif record.outcome == ERRORED or key in errors:
            result = {"status": "failed", "miou": None, "psnr": None, "error": record.error or errors.get(key, ""),
                      "spec": key}
        else:
            return None
        records.append(point_record(axis, row, level, seed, result, key))
    return records
