"""One point of the stability suite as a trial of the study engine: its point function and what it loads once.

The suite's study runs its points one after another in one process (``StudySettings.reuse_actors``): the first
point loads the test scenes, each zero-shot row's pretrained model (its method's ``eval_model``) and what the
trained rows start from (:func:`suite_for`), the next ones reuse them. A point returns the result of its spec
(``suite.compute_spec``), which the engine keeps in the trial's record, and reports its mIoU to Tune.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import ray
import torch

from sray.data_tools.shards.manifest import read_manifest
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.finetune.methods.registry import get_method
from sray.platform.finetune.scene_artifacts import checkpoint_sha256
from sray.platform.stability.point_spec import PointSpec
from sray.platform.stability.presets import Preset
from sray.platform.stability.rows import Row, SuiteModels
from sray.platform.stability.scene_points import SceneTraining, scene_settings
from sray.platform.stability.stress_scenes import load_scenes
from sray.platform.stability.suite import Suite, compute_spec
from sray.platform.sweep.study import TrialContext


@dataclass(frozen=True)
class SuiteInputs:
    """What a point's process loads to build the suite (paths and names only: cheap to send to every trial)."""

    preset: Preset
    shards: str
    """Shard folder holding the test scenes."""
    scenes: tuple[str, ...]
    """Test scenes the points are scored on."""
    rows: tuple[Row, ...]
    """The rows of the run (``rows.suite_rows``)."""
    models: SuiteModels
    """The pretrained models the rows are built from."""
    n_classes: int
    ignore_id: int
    device: str
    """Torch device the points run on."""


_loaded: list[tuple[SuiteInputs, Suite]] = []
"""The suite this process built last, with its inputs (one at most)."""


def scene_training(inputs: SuiteInputs) -> SceneTraining:
    """What the trained rows start from: the checkpoint's model and config, its checksum and the suite's fleet
    settings (:func:`~sray.platform.stability.scene_points.scene_settings`)."""
    base, train_cfg = model_from_checkpoint(inputs.models.checkpoint)
    shards = Path(inputs.shards)
    return SceneTraining(base=base, train_cfg=train_cfg, base_sha256=checkpoint_sha256(inputs.models.checkpoint),
                         cfg=scene_settings(inputs.preset, inputs.models.segmenter), shards=shards,
                         stored_neighbours=int(read_manifest(shards).neighbours["k"]), n_classes=inputs.n_classes,
                         ignore_id=inputs.ignore_id, device=torch.device(inputs.device))


def suite_for(inputs: SuiteInputs) -> Suite:
    """The suite of ``inputs``: built (scenes read, models loaded onto the device) on the first call of a
    process, reused while the inputs stay the same."""
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


def spec_point(spec: PointSpec, poison: bool) -> dict[str, Any]:
    """The plan's point of a spec: its fields (JSON values) and whether a fault drill poisons it."""
    return {**dataclasses.asdict(spec), "poison": poison}


def point_spec_of(point: dict[str, Any]) -> tuple[PointSpec, bool]:
    """The spec and the poison flag of a plan's point (:func:`spec_point` inverted)."""
    fields = {k: v for k, v in point.items() if k != "poison"}
    perturbation = fields["perturbation"]
    fields["perturbation"] = None if perturbation is None else (str(perturbation[0]), float(perturbation[1]))
    return PointSpec(**fields), bool(point["poison"])


def stability_point(point: dict[str, Any], ctx: TrialContext, inputs: SuiteInputs) -> dict[str, Any]:
    """The point function of the suite's study: the result of one spec (a failing method is a result too)."""
    spec, poison = point_spec_of(point)
    result = compute_spec(suite_for(inputs), spec, poison)
    if result["status"] == "ok":
        ctx.report({"miou": float(result["miou"])})
    return result


def trial_resources(device: str) -> dict[str, float]:
    """What one point reserves: every CPU of the local Ray (its torch threads), and one GPU on CUDA."""
    cpus = float(min(os.cpu_count() or 1, int(ray.cluster_resources().get("CPU", 1))))
    return {"CPU": max(cpus, 1.0), **({"GPU": 1.0} if device.startswith("cuda") else {})}
