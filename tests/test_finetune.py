"""One scene's finetune without Ray: early stopping, budgets, frozen modules."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch
from fleet_fixtures import one_thread, tiny_checkpoint, tiny_fleet_config  # noqa: F401
from hypothesis import given, settings
from hypothesis import strategies as st
from train_fixtures import tiny_shards  # noqa: F401

from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.finetune.scene_artifacts import adapted_keys, checkpoint_sha256
from sray.platform.finetune.scene_finetune import EarlyStopping, SceneTask, finetune_scene

pytestmark = pytest.mark.usefixtures("one_thread")


def _job(checkpoint: Path, shards: Path, out: Path, method: str = "sray", **finetune: object) -> SceneTask:
    return SceneTask(scene="synth_test_000", method=method, checkpoint=str(checkpoint),
                    base_sha256=checkpoint_sha256(checkpoint), shards=str(shards), out_dir=str(out), run=None,
                    attempt=1, config=tiny_fleet_config(**finetune))


def _naive_stop(values: list[float], patience: int, min_delta: float) -> int | None:
    """Index of the evaluation after which a finetune stops (None: never), written as a plain scan."""
    best = values[0]
    since = 0
    for i in range(1, len(values)):
        if values[i] > best + min_delta:
            best, since = values[i], 0
        else:
            since += 1
            if since == patience:
                return i
    return None


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0, 1), min_size=1, max_size=30), st.integers(1, 5), st.sampled_from([0.0, 0.01, 0.1]))
def test_early_stopping_matches_a_plain_scan(values, patience, min_delta):
    stopper = EarlyStopping(patience, min_delta)
    stopped_at = None
    for i, v in enumerate(values):
        stopper.update(v)
        if stopper.should_stop:
            stopped_at = i
            break
    assert stopped_at == _naive_stop(values, patience, min_delta)


def test_early_stopping_never_counts_nan_as_an_improvement():
    stopper = EarlyStopping(patience=2, min_delta=0.0)
    assert stopper.update(0.2) and not stopper.update(math.nan) and not stopper.should_stop
    assert not stopper.update(math.nan) and stopper.should_stop and stopper.best == 0.2


def test_flat_metric_stops_at_the_patience_limit(tiny_shards, tiny_checkpoint, tmp_path):
    # lr = 0: nothing changes, so the held-out mIoU is flat and patience ends the finetune.
    outcome = finetune_scene(_job(tiny_checkpoint, tiny_shards, tmp_path, lr=0.0, max_steps=60, eval_every=2,
                                  patience=2))
    r = outcome.result
    assert r["stopped_early"] and r["steps_used"] == 4 and r["max_steps"] == 60
    assert [p["step"] for p in r["curve"]] == [0, 2, 4]
    assert len({p["miou"] for p in r["curve"]}) == 1 and r["miou_after"] == r["miou_before"]
    assert 0.0 < r["curve"][1]["wall_s"] <= r["curve"][2]["wall_s"] == r["wall_s"]


def test_wall_clock_budget_stops_the_finetune(tiny_shards, tiny_checkpoint, tmp_path):
    r = finetune_scene(_job(tiny_checkpoint, tiny_shards, tmp_path, max_seconds=1e-6, max_steps=60)).result
    assert r["steps_used"] == 1 and not r["stopped_early"] and [p["step"] for p in r["curve"]] == [0, 1]


@pytest.mark.parametrize("method", ["sray", "semantic-nerf"])
def test_cpu_second_budget_stops_the_finetune(tiny_shards, tiny_checkpoint, tmp_path, method):
    """``finetune.max_cpu_seconds`` ends the finetune at the first step past it, counting this process's CPU time
    of the training steps (the held-out evaluations are left out)."""
    budget = 0.4
    r = finetune_scene(_job(tiny_checkpoint, tiny_shards, tmp_path, method, max_cpu_seconds=budget, max_steps=1000,
                            eval_every=10_000, patience=5)).result
    assert r["stop_reason"] == "max_cpu_seconds" and not r["stopped_early"] and 1 < r["steps_used"] < 1000
    per_step = r["cpu_s"] / r["steps_used"]
    assert budget <= r["cpu_s"] < budget + per_step + 0.05  # stopped by the first step past the budget
    assert [p["step"] for p in r["curve"]] == [0, r["steps_used"]]


def test_only_adapted_modules_change(tiny_shards, tiny_checkpoint, tmp_path):
    cfg_adapt = ("fine.classifier", "coarse.view_weights")
    outcome = finetune_scene(_job(tiny_checkpoint, tiny_shards, tmp_path, adapt=cfg_adapt, max_steps=3,
                                  eval_every=3, patience=5))
    base, _ = model_from_checkpoint(tiny_checkpoint)
    tuned, before = outcome.model.state_dict(), base.state_dict()
    adapted = set(adapted_keys(base, cfg_adapt))
    assert adapted and all(k.startswith(cfg_adapt) for k in adapted)
    for key, value in before.items():
        if key not in adapted:
            assert torch.equal(tuned[key].cpu(), value), key
    changed = [k for k in adapted if not torch.equal(tuned[k].cpu(), before[k])]
    # the best state is kept: when step 3 beat step 0 the adapted weights moved, otherwise none did
    assert bool(changed) == (outcome.result["miou_after"] > outcome.result["miou_before"])


def test_bf16_autocast_on_cpu_finetunes(tiny_shards, tiny_checkpoint, tmp_path):
    r = finetune_scene(_job(tiny_checkpoint, tiny_shards, tmp_path, precision="bf16", max_steps=2, eval_every=2)).result
    assert r["steps_used"] == 2 and all(math.isfinite(p["miou"]) and math.isfinite(p["psnr"]) for p in r["curve"])


@pytest.mark.gpu
def test_fp16_with_loss_scaling_on_cuda(tiny_shards, tiny_checkpoint, tmp_path):
    job = _job(tiny_checkpoint, tiny_shards, tmp_path, precision="fp16", max_steps=4, eval_every=2)
    job.config.gpus_per_task = 0.5
    outcome = finetune_scene(job)
    assert next(outcome.model.parameters()).is_cuda and outcome.result["steps_used"] == 4
    assert all(math.isfinite(p["miou"]) for p in outcome.result["curve"])
