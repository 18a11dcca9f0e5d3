"""Faults only a cluster has, each while a submitted tiny job trains: a worker node dies, the tracking server
goes away for a while. The job is stopped at a known step by the fault hook (``train.hold_at_steps``), the
fault is made, the job goes on; what it left is read back from PostgreSQL and Ray's actor table.

Marked ``cluster``; one cluster per session (``cluster_fixtures.local_cluster``, through conftest.py).
``SRAY_TEST_MLFLOW_OUTAGE_S`` sets how long the tracking server stays down (default 3 s).
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from cluster_fixtures import SRAY, ClusterInputs, LocalCluster
from cluster_jobs import (
    TRAIN_KEYS,
    eventually,
    finish,
    job_dir,
    metric_steps,
    psql,
    release,
    run_ids,
    start_job,
    submission_id,
    submit_argv,
    train_actors,
    wait_for_hold,
    worker_node_of,
)

from sray.platform.cluster.mlflow_server import healthy

pytestmark = pytest.mark.cluster

OUTAGE_S = float(os.environ.get("SRAY_TEST_MLFLOW_OUTAGE_S", "3"))
"""Seconds the tracking server stays stopped (``sray cluster restart --outage``)."""
STEPS = list(range(1, 11))
"""Steps a tiny job logs (``cluster_jobs.TINY_TRAIN``: 10 steps, every step logged)."""


def _cluster(cluster: LocalCluster, *args: str) -> subprocess.Popen:
    """``sray cluster ARGS --dir <the cluster>`` in the background."""
    return subprocess.Popen([*SRAY, "cluster", *args, "--dir", str(cluster.dir)], env=cluster.env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def test_worker_node_killed_mid_training_resumes_from_the_last_checkpoint(
        local_cluster: LocalCluster, cluster_inputs: ClusterInputs, tmp_path: Path) -> None:
    """One worker trains. The MLflow server is stopped before step 3, so the checkpoint at step 4 is written while
    steps 2-4 are still undelivered; before step 6, with the server still down, the node running rank 0 gets
    SIGKILL (its recorded ``ray start`` process group). Ray Train restarts the worker on another node from step 4,
    into the same MLflow run; once the server and the node are back (``sray cluster restart``), the run's history
    has no missing step."""
    name, log = "node-killed", tmp_path / "submit.log"
    folder, uri = job_dir(local_cluster, name), local_cluster.state.tracking_uri
    proc = start_job(local_cluster, submit_argv(local_cluster, cluster_inputs.shards, name), log,
                     faults="train.hold_at_steps=3,6")
    wait_for_hold(folder, 3, proc, log)
    server = _cluster(local_cluster, "restart", "--part", "mlflow", "--outage", str(OUTAGE_S))
    eventually(lambda: not healthy(uri), 30, "the MLflow server stopped")
    release(folder, 3)
    held = wait_for_hold(folder, 6, proc, log)
    assert not healthy(uri), f"the server came back before step 6; raise SRAY_TEST_MLFLOW_OUTAGE_S ({OUTAGE_S:g})"
    part = worker_node_of(local_cluster, held["pid"])
    killed_at = time.monotonic()
    os.killpg(local_cluster.state.processes[part]["pid"], signal.SIGKILL)
    node = _cluster(local_cluster, "restart", "--part", part)
    code, out = finish(proc, log, timeout=180)
    lost_s = time.monotonic() - killed_at
    restarted = [p.communicate(timeout=120)[0] for p in (server, node)]
    local_cluster.refresh()
    assert server.returncode == 0 and node.returncode == 0, restarted
    assert code == 0, out[-3000:]
    assert "[sray] resumed at step 4 (a restarted worker group)" in out

    actors = train_actors(local_cluster, submission_id(out))
    assert len(actors) == 2 and held["node_id"] in {a["node_id"] for a in actors}
    assert len({a["node_id"] for a in actors}) == 2, "the restarted worker ran on another node"
    [run] = run_ids(local_cluster, name)
    for key in TRAIN_KEYS:
        assert sorted(set(metric_steps(local_cluster, run, key))) == STEPS, key
    print(f"\n[cluster fault] node {part} killed at step 6: job done {lost_s:.1f} s later")


def test_tracking_server_stopped_mid_run_loses_no_metric_and_training_goes_on(
        local_cluster: LocalCluster, cluster_inputs: ClusterInputs, tmp_path: Path) -> None:
    """The MLflow server is stopped once rank 0 waits before step 2 and stays down ``OUTAGE_S`` s (then its
    restart). Steps 3-7 train and log while it is down (rank 0 reaches its pause before step 7 with the server
    still down); afterwards PostgreSQL holds every metric of every step exactly once, those of steps 3-7 with
    timestamps inside the outage."""
    name, log = "mlflow-outage", tmp_path / "submit.log"
    folder = job_dir(local_cluster, name)
    uri = local_cluster.state.tracking_uri
    proc = start_job(local_cluster, submit_argv(local_cluster, cluster_inputs.shards, name), log,
                     faults="train.hold_at_steps=2,7")
    wait_for_hold(folder, 2, proc, log)
    restart = _cluster(local_cluster, "restart", "--part", "mlflow", "--outage", str(OUTAGE_S))
    eventually(lambda: not healthy(uri), 30, "the MLflow server stopped")
    down_ms = int(time.time() * 1000)
    release(folder, 2)
    wait_for_hold(folder, 7, proc, log)
    assert not healthy(uri), f"the server came back before step 7; raise SRAY_TEST_MLFLOW_OUTAGE_S ({OUTAGE_S:g})"
    restarted = restart.communicate(timeout=120)[0]
    up_ms = int(time.time() * 1000)
    assert restart.returncode == 0 and healthy(uri), restarted
    release(folder, 7)
    code, out = finish(proc, log)
    local_cluster.refresh()
    assert code == 0, out[-3000:]

    [run] = run_ids(local_cluster, name)
    for key in TRAIN_KEYS:
        assert metric_steps(local_cluster, run, key) == STEPS, key
    logged_meanwhile = psql(local_cluster, f"SELECT DISTINCT step FROM metrics WHERE run_uuid = '{run}' AND "
                                           f"key = 'train/loss' AND timestamp BETWEEN {down_ms} AND {up_ms}")
    assert sorted(int(s) for [s] in logged_meanwhile) == [3, 4, 5, 6, 7]
    print(f"\n[cluster fault] MLflow server down {(up_ms - down_ms) / 1000:.1f} s (outage {OUTAGE_S:g} s + "
          "restart); no metric lost")
