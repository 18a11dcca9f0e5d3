"""``sray train`` end to end on two gloo workers: learning, DDP sync, guards, checkpoints, resume, MLflow."""

from __future__ import annotations

import copy
import json
import time
from pathlib import Path

import pytest
import torch
from injected_faults import injected_faults
from mlflow.tracking import MlflowClient
from train_fixtures import tiny_config, tiny_shards  # noqa: F401

from sray.platform.checkpoints.folders import load_checkpoint
from sray.platform.common.fault_hook import KILL_MARKER
from sray.platform.train.launcher import budget_spent, launch_training
from sray.platform.train.resources import InfeasibleRequest

pytestmark = pytest.mark.slow


def _history(cfg, key: str) -> list[tuple[int, float]]:
    client = MlflowClient(cfg.run.tracking_uri)
    exp = client.get_experiment_by_name(cfg.run.experiment)
    runs = client.search_runs([exp.experiment_id], filter_string=f"attributes.run_name = '{cfg.run.name}'")
    assert len(runs) == 1, f"expected one MLflow run for {cfg.run.name}, found {len(runs)}"
    return [(m.step, m.value) for m in client.get_metric_history(runs[0].info.run_id, key)]


@pytest.fixture(scope="module")
def uninterrupted(ray_session, tiny_shards, tmp_path_factory):  # noqa: F811
    """20 steps on 2 workers with a NaN injected at step 7."""
    cfg = tiny_config(tiny_shards, tmp_path_factory.mktemp("u"), name="uninterrupted")
    with injected_faults("train.nan_at_step=7"):
        outcome = launch_training(cfg)
    return cfg, outcome


def test_two_workers_learn_and_stay_in_sync(uninterrupted) -> None:
    """The loss falls over 20 steps and the ranks' parameters are identical at every checkpoint."""
    cfg, outcome = uninterrupted
    assert outcome.status == "FINISHED"
    losses = [v for _, v in sorted(_history(cfg, "train/loss"))]
    assert len(losses) >= 15
    assert sum(losses[-4:]) / 4 < sum(losses[:4]) / 4, losses
    divergence = _history(cfg, "ddp/param_divergence")
    assert divergence and all(v == 0.0 for _, v in divergence), divergence


def test_nonfinite_loss_is_skipped_and_counted(uninterrupted) -> None:
    """The NaN at step 7 skipped exactly one step; training went on to the end."""
    cfg, outcome = uninterrupted
    skipped = dict(_history(cfg, "train/skipped_steps"))
    assert skipped[max(skipped)] == 1.0
    state = load_checkpoint(outcome.latest_checkpoint)
    assert state["step"] == cfg.optim.steps


def test_mlflow_store_holds_everything(uninterrupted) -> None:
    """Params, metrics, the config artifact, a PNG render and a registered model version."""
    cfg, outcome = uninterrupted
    client = MlflowClient(cfg.run.tracking_uri)
    run = client.get_run(outcome.run.run_id)
    assert run.data.params["optim.steps"] == "20" and run.info.status == "FINISHED"
    assert {"train/loss", "train/lr", "val/miou", "zeroshot/miou", "train/rays_per_s", "train/data_wait_share",
            "train/memory_mb", "train/cpu_seconds", "system/node0/cpu_utilization_percentage",
            "system/node0/system_memory_usage_megabytes"} <= set(run.data.metrics)
    # the validation protocol, logged once: strided renders (data.held_out.stride 2), so no SSIM was logged
    rule = json.loads((Path(cfg.data.shards) / "manifest.json").read_text())["neighbours"]
    assert run.data.params["protocol.source_rule"] == f"{rule['rule']} v{rule['version']}"
    assert run.data.params["protocol.stride"] == "2" and run.data.params["protocol.n_source"] == "3"
    assert "(stride 2), so no SSIM" in run.data.tags["sray.protocol"]
    assert not {"val/ssim", "zeroshot/ssim"} & set(run.data.metrics)
    paths = [a.path for a in client.list_artifacts(run.info.run_id)]
    assert "config.json" in paths
    renders = [a.path for folder in ("renders/val", "renders/zeroshot")
               for a in client.list_artifacts(run.info.run_id, folder)]
    assert any(p.endswith(".png") for p in renders), renders
    versions = client.search_model_versions(f"name = '{cfg.run.register_model}'")
    assert any(v.run_id == run.info.run_id for v in versions)


def test_resume_equals_uninterrupted(uninterrupted, tiny_shards, tmp_path_factory) -> None:  # noqa: F811
    """Checkpointed every 4 steps instead of 5 but with the reference's 5-step loader epochs, stopped mid-epoch
    after step 7 and resumed to step 20: the same parameters as uninterrupted (the data order follows
    ``data.epoch_steps``, not the checkpoint interval; the resume replays epoch 1 to its offset 2)."""
    ref_cfg, ref = uninterrupted
    assert ref_cfg.data.epoch_steps == 0 and ref_cfg.run.ckpt_every == 5  # the reference's epochs are 5 steps
    out = tmp_path_factory.mktemp("r")
    cfg = tiny_config(tiny_shards, out, name="stopped", ckpt_every=4)
    cfg.data.epoch_steps = 5
    with injected_faults("train.nan_at_step=7;train.stop_after_step=7"):
        first = launch_training(cfg)
    assert first.status == "KILLED" and load_checkpoint(first.latest_checkpoint)["step"] == 7
    with injected_faults("train.nan_at_step=7"):
        second = launch_training(cfg, resume=True)
    assert second.status == "FINISHED"
    got, want = load_checkpoint(second.latest_checkpoint), load_checkpoint(ref.latest_checkpoint)
    for key in want["model"]:
        torch.testing.assert_close(got["model"][key], want["model"][key], rtol=1e-5, atol=1e-6, msg=key)


def test_killed_worker_resumes_without_metric_gaps(ray_session, tiny_shards, tmp_path) -> None:  # noqa: F811
    """rank 0 dies abruptly at step 12 (first attempt): the job restarts from its checkpoint and ends."""
    cfg = tiny_config(tiny_shards, tmp_path, name="killed")
    with injected_faults("train.kill_at_step=12"):
        outcome = launch_training(cfg)
    assert outcome.status == "FINISHED"
    steps = sorted({s for s, _ in _history(cfg, "train/loss")})
    assert steps == list(range(1, cfg.optim.steps + 1)), steps
    assert (Path(cfg.run.output_dir) / "killed" / KILL_MARKER).exists()


def test_infeasible_request_fails_fast(ray_session, tiny_shards, tmp_path) -> None:  # noqa: F811
    """More workers than the cluster's CPUs: refused in seconds, naming what is available."""
    cfg = tiny_config(tiny_shards, tmp_path, name="too-big", workers=5)
    start = time.perf_counter()
    with pytest.raises(InfeasibleRequest, match="2 CPUs"):
        launch_training(cfg)
    assert time.perf_counter() - start < 30


def test_cpu_budget_stops_within_a_step_and_the_2d_warm_up_keeps_ranks_in_sync(ray_session, tiny_shards,  # noqa: F811
                                                                                 tmp_path) -> None:
    """``optim.cpu_seconds`` ends the job at the first step whose CPU seconds (both ranks, summed) reach the
    budget, long before the step cap; the learning rate decays with the CPU fraction; the 2D warm-up steps
    (source labels only) and the source-view term after them keep the two DDP ranks identical."""
    cfg = tiny_config(tiny_shards, tmp_path, name="budget")
    cfg.optim.steps, cfg.optim.cpu_seconds, cfg.optim.warmup_2d_steps = 400, 12.0, 3
    cfg.model.lambda_src_sem = 0.5
    cfg.run.val_every, cfg.run.ckpt_every, cfg.run.system_metrics_s = 1000, 1000, 0.0
    outcome = launch_training(cfg)
    assert outcome.status == "FINISHED"
    cpu = sorted(_history(cfg, "train/cpu_seconds"))
    last_step, spent = cpu[-1]
    assert last_step < cfg.optim.steps and spent >= cfg.optim.cpu_seconds > cpu[-2][1], cpu[-3:]
    counters = load_checkpoint(outcome.latest_checkpoint)["counters"]
    assert counters["cpu_seconds"] == pytest.approx(spent)
    assert counters["wall_seconds"] > 0 and counters["peak_memory_mb"] > 0  # what the recipe cards read
    job_dir, larger = Path(cfg.run.output_dir) / cfg.run.name, copy.deepcopy(cfg)
    larger.optim.cpu_seconds = 2 * spent
    assert budget_spent(job_dir, cfg) and not budget_spent(job_dir, larger)  # what a resume or a bench cell reads
    lr = dict(_history(cfg, "train/lr"))
    assert lr[last_step] < 0.5 * cfg.optim.lr  # decayed by the CPU fraction, not by last_step / 400
    assert all(lr[s] > lr[s + 1] for s in range(1, last_step - 1))  # decays from the first step, 2D ones included
    src_steps, ray_steps = ({s for s, _ in _history(cfg, key)} for key in ("train/sem_src", "train/sem_fine"))
    assert src_steps == set(range(1, last_step + 1))  # every step, warm-up included
    assert ray_steps == set(range(4, last_step + 1))  # rays rendered only after the 3 warm-up steps
    divergence = _history(cfg, "ddp/param_divergence")
    assert divergence and all(v == 0.0 for _, v in divergence), divergence
    run = MlflowClient(cfg.run.tracking_uri).get_run(outcome.run.run_id)
    assert not any(k.startswith("system/") for k in run.data.metrics)  # run.system_metrics_s = 0: switched off
    assert (run.data.params["protocol.inputs"], run.data.params["protocol.train_inputs"]) == ("rgb", "rgb")
