"""``sray sweep`` end to end on tiny data: real training jobs as Tune trials, ASHA, a CPU-second budget, a
failing trial, the parent/child tracked runs, and a driver killed mid-sweep then resumed."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import psutil
import pytest
import yaml
from injected_faults import injected_faults
from mlflow.tracking import MlflowClient
from train_fixtures import tiny_config, tiny_shards  # noqa: F401

from sray.platform.common.fault_hook import ENV_VAR, hold_paths
from sray.platform.config.recipes import get_recipe
from sray.platform.sweep.driver import SweepResult, run_sweep
from sray.platform.sweep.options import SweepOptions, SweepRequest
from sray.platform.sweep.spec import parse_assignment
from sray.platform.sweep.study import read_history, read_record, read_stop_request, trial_folder
from sray.platform.tracking.params import flatten_config

pytestmark = pytest.mark.slow

CPU_BUDGET = 6.0
"""CPU seconds per trial of the shared sweep: a handful of tiny steps."""
STEP_CAP = 40
"""Steps per trial of the shared sweep: a cap the CPU budget ends first."""
GRACE = 4
"""ASHA's first rung: two validations in, where the learning arm is above lr = 0 on the tiny scenes (at step 2 the
first steps of the warm-up can still leave it level with or under the untrained weights)."""


def _release_in_order(folder: Path, stop: threading.Event) -> None:
    """The two trials run at once and both pause before their second step: let t000 go first, and t001 only once
    the sweep has t000's first-rung result, so that ASHA judges t001 against it (and not the other way round)."""
    (first, go_first), (second, go_second) = (hold_paths(folder / "jobs" / f"toy-{k}", 1) for k in ("t000", "t001"))
    while not stop.wait(0.2):
        if first.exists():
            go_first.touch()
        if second.exists() and any(e.get("step") == GRACE for e in read_history(trial_folder(folder, "t000"))):
            go_second.touch()


@pytest.fixture(scope="module")
def toy_sweep(ray_session, tiny_shards, tmp_path_factory) -> tuple[SweepResult, Any]:  # noqa: F811
    """Learning rate grid(3e-3, 0, 1e-3) on one worker per trial, two trials at a time: ASHA on val/psnr from
    step ``GRACE``, a CPU-second budget, and trial t002 failing through the fault hook."""
    out = tmp_path_factory.mktemp("sweep")
    cfg = tiny_config(tiny_shards, out, workers=1, val_every=2, ckpt_every=2)
    request = SweepRequest(name="toy", out=out / "sweeps", base=cfg,
                           params=[parse_assignment("optim.lr=grid(3e-3, 0, 1e-3)")],
                           options=SweepOptions(metric="val/psnr", steps=STEP_CAP, cpu_seconds=CPU_BUDGET, grace=GRACE,
                                                reduction_factor=2, max_concurrent=2))
    stop = threading.Event()
    releaser = threading.Thread(target=_release_in_order, args=(request.out.resolve() / "toy", stop), daemon=True)
    releaser.start()
    try:
        with injected_faults("sweep.fail_trials=t002;train.hold_at_steps=1"):
            result = run_sweep(request)
    finally:
        stop.set()
    return result, cfg


def _outcome(result: SweepResult, key: str) -> Any:
    return next(o for o in result.outcomes if o.key == key)


def _run_named(client: MlflowClient, experiment_id: str, name: str) -> Any:
    runs = client.search_runs([experiment_id], filter_string=f"attributes.run_name = '{name}'")
    assert len(runs) == 1, f"expected one run named {name}, found {len(runs)}"
    return runs[0]


def _cpu_seconds(cfg: Any, run_name: str) -> list[tuple[int, float]]:
    """``train/cpu_seconds`` of a trial's training run, by step."""
    client = MlflowClient(cfg.run.tracking_uri)
    run = _run_named(client, client.get_experiment_by_name(cfg.run.experiment).experiment_id, run_name)
    return sorted((m.step, m.value) for m in client.get_metric_history(run.info.run_id, "train/cpu_seconds"))


def test_asha_stops_the_arm_that_cannot_learn(toy_sweep) -> None:
    """lr = 0 scores below the learning arm at the first rung (``GRACE``): stopped there, before its CPU budget."""
    result, cfg = toy_sweep
    learner, frozen = _outcome(result, "t000"), _outcome(result, "t001")
    assert frozen.reason == "stopped", frozen
    assert read_stop_request(trial_folder(result.folder, "t001")) == {"by": "scheduler", "at": GRACE}
    assert frozen.last["step"] < learner.last["step"] and _cpu_seconds(cfg, "toy-t001")[-1][1] < CPU_BUDGET
    assert learner.last_value("val/psnr") > frozen.last_value("val/psnr")


def test_a_cpu_second_budget_stops_a_trial_within_one_step(toy_sweep) -> None:
    """The learning arm ends at the first step whose summed CPU seconds reach the budget, well before its step cap."""
    result, cfg = toy_sweep
    spent = _cpu_seconds(cfg, "toy-t000")
    assert _outcome(result, "t000").reason == "finished" and spent[-1][0] < STEP_CAP
    assert spent[-2][1] < CPU_BUDGET <= spent[-1][1], spent[-3:]


def test_a_failing_trial_is_recorded_and_the_others_finish(toy_sweep) -> None:
    """t002 raises through the fault hook: errored with its error, while t000 finished and t001 was stopped."""
    result, _ = toy_sweep
    failed = _outcome(result, "t002")
    assert failed.reason == "errored" and "InjectedFailure" in failed.note and "t002" in failed.note
    assert [o.reason for o in result.outcomes] == ["finished", "stopped", "errored"] and result.complete
    table = (result.folder / "results.md").read_text()
    assert "Best: t000" in table and "| t002 | 1e-3 | errored |" in table
    assert {p.name for p in result.files} == {"results.md", "results.csv", "results.json", "metric_vs_time.png"}


def test_the_sweep_is_one_parent_run_with_a_child_per_trial(toy_sweep) -> None:
    """Through the tracker's store: the parent, its three nested children with their stop reasons, statuses and
    final checkpoints, the results logged to the parent, the best model registered under the sweep's alias."""
    result, cfg = toy_sweep
    client = MlflowClient(cfg.run.tracking_uri, registry_uri=cfg.run.tracking_uri)
    experiment = client.get_experiment_by_name(cfg.run.experiment).experiment_id
    parent = _run_named(client, experiment, "toy")
    assert parent.data.tags["sray.kind"] == "sweep" and parent.info.status == "FINISHED"
    assert parent.data.params["sweep.params.optim.lr"] == "grid(3e-3, 0, 1e-3)"
    assert parent.data.metrics["trials/stopped"] == 1.0 and parent.data.metrics["trials/errored"] == 1.0
    assert {a.path for a in client.list_artifacts(parent.info.run_id, "results")} >= {
        "results/results.md", "results/metric_vs_time.png"}
    children = client.search_runs([experiment], filter_string=f"tags.mlflow.parentRunId = '{parent.info.run_id}'")
    by_trial = {c.data.tags["sray.trial"]: c for c in children}
    assert sorted(by_trial) == ["t000", "t001", "t002"]
    expected = {"t000": ("finished", "FINISHED"), "t001": ("stopped", "KILLED"), "t002": ("errored", "FAILED")}
    for key, (reason, status) in expected.items():
        assert (by_trial[key].data.tags["sray.stop_reason"], by_trial[key].info.status) == (reason, status), key
    assert by_trial["t001"].data.params["optim.lr"] == "0.0" and by_trial["t002"].data.params["optim.lr"] == "1e-3"
    for key in ("t000", "t001"):
        assert [a.path for a in client.list_artifacts(by_trial[key].info.run_id, "checkpoint")], key
    version = client.get_model_version_by_alias(cfg.run.register_model, "sweep-toy")
    assert version.run_id == by_trial["t000"].info.run_id


def _spec_file(path: Path, shards: Path, out: Path) -> Path:
    """A spec file training the tests' tiny config, validated and saved every 2 steps: two trials at once, one of
    2 steps and one of 4 (``optim.steps`` swept like any field)."""
    tiny = flatten_config(tiny_config(shards, out, workers=1, val_every=2, ckpt_every=2).to_dict())
    recipe = flatten_config(get_recipe("synth-small").to_dict())
    fixed = {k: str(v) for k, v in tiny.items() if v != recipe[k] and not isinstance(v, (list, tuple))}
    path.write_text(yaml.safe_dump({"recipe": "synth-small", "set": fixed, "params": {"optim.steps": "grid(2, 4)"},
                                    "metric": "val/psnr", "scheduler": "none", "max_concurrent": 2}))
    return path


def _sweep_cli(args: list[str], log: Path, env: dict[str, str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "sray.jobs.cli", "sweep", *args], cwd=cwd, env=env,
                            stdout=open(log, "ab"), stderr=subprocess.STDOUT, start_new_session=True)


def _kill_mid_sweep(driver: subprocess.Popen, folder: Path, timeout_s: float) -> dict[str, Any]:
    """SIGKILL the driver's whole session once t000 has finished and t001 waits at step 2 (its step-2 checkpoint
    saved). Returns the waiting worker's marker (its pid)."""
    marker, _ = hold_paths(folder / "jobs" / "kill-t001", 2)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and driver.poll() is None:
        if marker.exists() and read_record(trial_folder(folder, "t000")).outcome == "finished":
            os.killpg(driver.pid, signal.SIGKILL)
            driver.wait()
            return json.loads(marker.read_text())
        time.sleep(0.5)
    pytest.fail(f"t001 never waited at step 2 after t000 finished (driver exit code {driver.poll()})")


def _wait_for_exit(pid: int, timeout_s: float) -> bool:
    """True once process ``pid`` is gone (or a zombie) within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            if psutil.Process(pid).status() == psutil.STATUS_ZOMBIE:
                return True
        except psutil.NoSuchProcess:
            return True
        time.sleep(0.5)
    return False


def test_a_killed_sweep_resumes_without_training_anything_twice(tiny_shards, tmp_path: Path) -> None:  # noqa: F811
    """SIGKILL the driver once t000 (2 steps) is done and t001 is at step 2 of 4; ``--resume`` finishes the sweep:
    t000 is not launched again, t001 continues from its checkpoint, each trial's steps over both runs are its
    budget's, each once."""
    spec = _spec_file(tmp_path / "spec.yaml", tiny_shards, tmp_path)
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    folder = tmp_path / "sweeps" / "kill"
    common = ["--out", str(tmp_path / "sweeps"), "--tracking-uri", uri]
    env = os.environ | {ENV_VAR: "train.hold_at_steps=2", "RAY_USAGE_STATS_ENABLED": "0"}
    log = tmp_path / "driver.log"
    held = _kill_mid_sweep(_sweep_cli([str(spec), "--name", "kill", *common], log, env, tmp_path), folder, 400)
    if not _wait_for_exit(held["pid"], 60):
        os.kill(held["pid"], signal.SIGKILL)
        pytest.fail(f"worker {held['pid']} outlived the killed driver")
    resumed = _sweep_cli(["--resume", "kill", *common], log, {k: v for k, v in env.items() if k != ENV_VAR}, tmp_path)
    assert resumed.wait(timeout=400) == 0, log.read_text()[-3000:]
    results = json.loads((folder / "results.json").read_text())
    assert [t["reason"] for t in results["trials"]] == ["finished", "finished"]
    assert [len(read_record(trial_folder(folder, k)).launches) for k in ("t000", "t001")] == [1, 2]
    client = MlflowClient(uri)
    experiment = client.get_experiment_by_name(get_recipe("synth-small").run.experiment).experiment_id
    for key, budget in (("t000", 2), ("t001", 4)):
        run = _run_named(client, experiment, f"kill-{key}")
        steps = sorted(m.step for m in client.get_metric_history(run.info.run_id, "train/loss"))
        assert steps == list(range(1, budget + 1)), (key, steps)
    second_launch = [e["step"] for e in results["trials"][1]["history"] if e["launch"] == 1]
    assert second_launch and min(second_launch) > 2, "t001's second launch started from its step-2 checkpoint"
