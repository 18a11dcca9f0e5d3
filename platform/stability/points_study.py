"""The stability suite's points as an engine study (``engine.run_missing``), one trial per point key under
``<out>/study/<preset>/`` in one process (:func:`suite_for`); ``definition.json`` (docs/stability.md, "Outputs")."""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import ray
import torch

from sray.data_tools.atomic import atomic_write_json
from sray.data_tools.shards.manifest import read_manifest
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.finetune.methods.registry import get_method
from sray.platform.finetune.scene_artifacts import checkpoint_sha256
from sray.platform.stability.axes import PointSpec, Preset
from sray.platform.stability.rows import Row, SuiteModels
from sray.platform.stability.scene_points import SceneTraining, scene_settings
from sray.platform.stability.stress_scenes import load_scenes
from sray.platform.stability.suite import Planned, Suite, compute_spec, point_key, point_record
from sray.platform.sweep.engine import missing, run_missing
from sray.platform.sweep.outcomes import TrialOutcome
from sray.platform.sweep.study import ERRORED, FINISHED, StudySettings, TrialContext, read_record, trial_folder
from sray.platform.train.launcher import init_ray

STUDY_DIR = "study"
"""Folder of ``--out`` holding one study per preset name."""
DEFINITION_FILE = "definition.json"
"""The preset definition and the models the points of a study folder were made with."""


@dataclass(frozen=True)
class SuiteInputs:
    """What a point's process loads to build the suite (paths and names only: cheap to send to every trial)."""

    preset: Preset
    shards: str
    """Shard folder holding the test scenes."""
    scenes: tuple[str, ...]
    rows: tuple[Row, ...]
    """The rows of the run (``rows.suite_rows``)."""
    models: SuiteModels
    n_classes: int
    ignore_id: int
    device: str


_loaded: list[tuple[SuiteInputs, Suite]] = []
"""The suite this process built last, with its inputs (one at most)."""


def scene_training(inputs: SuiteInputs) -> SceneTraining:
    """What the trained rows start from: the checkpoint's model and config, its checksum, the suite's fleet settings."""
    base, train_cfg = model_from_checkpoint(inputs.models.checkpoint)
    shards = Path(inputs.shards)
    return SceneTraining(base=base, train_cfg=train_cfg, base_sha256=checkpoint_sha256(inputs.models.checkpoint),
                         cfg=scene_settings(inputs.preset, inputs.models.segmenter), shards=shards,
                         stored_neighbours=int(read_manifest(shards).neighbours["k"]), n_classes=inputs.n_classes,
                         ignore_id=inputs.ignore_id, device=torch.device(inputs.device))


def suite_for(inputs: SuiteInputs) -> Suite:
    """The suite of ``inputs``: built on a process's first call, reused while the inputs stay the same."""
    if not _loaded or _loaded[0][0] != inputs:
        _loaded.clear()
        models = {row.name: get_method(row.method).eval_model(row.request(inputs.models, inputs.device))
                  for row in inputs.rows if not row.trained}
        training = scene_training(inputs) if any(row.trained for row in inputs.rows) else None
        net_cfg = (training.base if training else model_from_checkpoint(inputs.models.checkpoint)[0]).cfg
        suite = Suite(inputs.preset, load_scenes(Path(inputs.shards), list(inputs.scenes)),
                      {row.name: row for row in inputs.rows}, models, training,
                      (net_cfg.n_coarse, net_cfg.min_source_depth))
        _loaded.append((inputs, suite))
    return _loaded[0][1]


def stability_point(point: dict[str, Any], ctx: TrialContext, inputs: SuiteInputs) -> dict[str, Any]:
    """The point function of the suite's study: the result of one spec (a failing method is a result too)."""
    fields = {k: v for k, v in point.items() if k != "poison"}
    if fields["perturbation"] is not None:
        fields["perturbation"] = (str(fields["perturbation"][0]), float(fields["perturbation"][1]))
    result = compute_spec(suite_for(inputs), PointSpec(**fields), bool(point["poison"]))
    if result["status"] == "ok":
        ctx.report({"miou": float(result["miou"])})
    return result


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
    """Point key -> the plan's point (the spec's fields, ``poison``), each key once, in the order of ``planned``."""
    plan: dict[str, dict[str, Any]] = {}
    for axis, row, level, seed in planned:
        key, spec, poison = point_key(preset, axis, row, level, seed)
        plan.setdefault(key, {**dataclasses.asdict(spec), "poison": poison})
    return plan


def run_points(out: Path, planned: Planned, inputs: SuiteInputs) -> list[TrialOutcome]:
    """Run the points of ``planned`` without a result, one at a time on all local CPUs (a GPU on CUDA); all outcomes."""
    preset = inputs.preset
    study = study_folder(out, preset)
    check_definition(study, preset, inputs.models)
    plan = study_plan(preset, planned)
    resources = {"CPU": 1.0}
    if missing(study, plan):
        init_ray(None)
        cpus = float(min(os.cpu_count() or 1, int(ray.cluster_resources().get("CPU", 1))))
        resources = {"CPU": max(cpus, 1.0), **({"GPU": 1.0} if inputs.device.startswith("cuda") else {})}
    settings = StudySettings(folder=study, metric="miou", mode="max", reuse_actors=True, label="stability",
                             trial_resources=resources)
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
