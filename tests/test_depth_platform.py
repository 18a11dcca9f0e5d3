"""A checkpoint trained with the depth loss (``model.lambda_depth`` > 0) through the platform: its fleet finetune
runs without the query depth (the term is absent) and every descriptor says ``inputs: rgb`` with
``train_inputs: rgbd`` (``sray eval``, the fleet's result)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: F401  (pytest fixtures, used by name)
from train_fixtures import tiny_config, tiny_shards  # noqa: F401  (pytest fixture, used by name)

from sray.data_tools.shards.manifest import read_manifest

N_SOURCE = 3


def _depth_checkpoint(shards: Path, root: Path) -> Path:
    """An untrained tiny S-Ray checkpoint with ``model.lambda_depth = 0.5``, in a ``sray train`` job layout."""
    from sray.platform.checkpoints.folders import write_checkpoint
    from sray.platform.train.state import build_training, training_state

    cfg = tiny_config(shards, root)
    cfg.model.lambda_depth = 0.5
    model, optimizer, scheduler = build_training(cfg)
    return write_checkpoint(training_state(model.net, optimizer, scheduler, None, 3, cfg, None, {}),
                            root / "jobs" / "depth" / "checkpoints" / "step_000000003", 3)


def test_a_finetune_of_a_depth_trained_checkpoint_runs_without_depth_and_says_so(tiny_shards: Path,
                                                                                tmp_path: Path) -> None:
    from fleet_fixtures import tiny_fleet_config

    from sray.platform.finetune.scene_artifacts import checkpoint_sha256
    from sray.platform.finetune.scene_finetune import SceneTask, finetune_scene

    ckpt = _depth_checkpoint(tiny_shards, tmp_path)
    scene = next(s for s, e in read_manifest(tiny_shards).scenes.items() if e.meta["role"] == "test")
    task = SceneTask(scene=scene, method="sray", checkpoint=str(ckpt), base_sha256=checkpoint_sha256(ckpt),
                     shards=str(tiny_shards), out_dir=str(tmp_path / "ft"), run=None, attempt=1,
                     config=tiny_fleet_config(max_steps=2, eval_every=2))
    result = finetune_scene(task).result
    assert (result["protocol"]["inputs"], result["protocol"]["train_inputs"]) == ("rgb", "rgbd")
    assert result["steps_used"] == 2 and all(np.isfinite(p["miou"]) for p in result["curve"])


def test_sray_eval_of_a_depth_trained_checkpoint_says_rgb_inputs_rgbd_training(tiny_shards: Path, tmp_path: Path,
                                                                                mlflow_uri: str) -> None:
    from sray.jobs.cli import main

    ckpt = _depth_checkpoint(tiny_shards, tmp_path)
    out = tmp_path / "eval"
    assert main(["eval", "--checkpoint", str(ckpt), "--data", str(tiny_shards), "--n-source", str(N_SOURCE),
                 "--stride", "8", "--out", str(out), "--tracking-uri", mlflow_uri]) == 0
    protocol = json.loads((out / "metrics.json").read_text())["protocol"]
    assert (protocol["inputs"], protocol["train_inputs"]) == ("rgb", "rgbd")
