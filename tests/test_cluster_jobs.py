"""``sray submit`` on the local cluster: a job trains on the worker nodes, logs to the PostgreSQL-backed MLflow
server, checkpoints on the shared storage and ``--wait`` exits with its status; a job whose driver is killed
continues with ``--resume``.

Marked ``cluster``; one cluster per session (``cluster_fixtures.local_cluster``, through conftest.py).
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest
from cluster_fixtures import ClusterInputs, LocalCluster
from cluster_jobs import (
    TRAIN_KEYS,
    dashboard_get,
    eventually,
    finish,
    job_dir,
    metric_steps,
    node_ids,
    psql,
    run_ids,
    start_job,
    submission_id,
    submit_argv,
    train_actors,
    wait_for_hold,
)

pytestmark = pytest.mark.cluster

STEPS = list(range(1, 11))
"""Steps a tiny job logs (``cluster_jobs.TINY_TRAIN``: 10 steps, every step logged)."""


def test_submitted_job_trains_on_the_worker_nodes_logs_to_the_server_and_checkpoints_on_shared_storage(
        local_cluster: LocalCluster, cluster_inputs: ClusterInputs, tmp_path: Path) -> None:
    """Two Ray Train workers, one per worker node (Ray's actor table), none on the head; one FINISHED run in
    PostgreSQL with every step of every per-step metric once; checkpoints and the registered model's files
    where the cluster keeps them; ``--wait`` exits 0."""
    name, log = "submit-two-nodes", tmp_path / "submit.log"
    argv = submit_argv(local_cluster, cluster_inputs.shards, name, workers=2, run__register_model="sray-cluster")
    code, out = finish(start_job(local_cluster, argv, log), log)
    assert code == 0 and "SUCCEEDED" in out, out[-3000:]

    workers = {node for node, head in node_ids(local_cluster).items() if not head}
    actors = train_actors(local_cluster, submission_id(out))
    assert len(actors) == 2 and {a["node_id"] for a in actors} == workers

    [run] = run_ids(local_cluster, name)
    assert psql(local_cluster, f"SELECT status FROM runs WHERE run_uuid = '{run}'") == [["FINISHED"]]
    for key in TRAIN_KEYS:
        assert metric_steps(local_cluster, run, key) == STEPS, key
    checkpoints = job_dir(local_cluster, name) / "checkpoints"
    assert (checkpoints / "step_000000010" / "state.pt").is_file()
    [[version, run_of_version]] = psql(local_cluster, "SELECT version, run_id FROM model_versions "
                                                      "WHERE name = 'sray-cluster'")
    assert run_of_version == run
    uploaded = list((local_cluster.dir / "artifacts").glob(f"*/{run}/artifacts/checkpoint/state.pt"))
    assert len(uploaded) == 1, "the registered checkpoint went through the server's proxied artifact store"


def test_killed_driver_fails_the_job_and_resume_continues_from_its_checkpoint(
        local_cluster: LocalCluster, cluster_inputs: ClusterInputs, tmp_path: Path) -> None:
    """The driver is SIGKILLed while rank 0 waits before step 6 (checkpoint at step 4): ``--wait`` exits 1
    (FAILED); ``sray submit --resume`` restarts at step 4 into the same MLflow run, and its history holds every
    step 1-10."""
    name, log = "driver-killed", tmp_path / "first.log"
    folder = job_dir(local_cluster, name)
    proc = start_job(local_cluster, submit_argv(local_cluster, cluster_inputs.shards, name), log,
                     faults="train.hold_at_steps=6")
    wait_for_hold(folder, 6, proc, log)
    driver = dashboard_get(local_cluster, f"/api/jobs/{submission_id(log.read_text())}")["driver_info"]
    os.kill(int(driver["pid"]), signal.SIGKILL)
    code, out = finish(proc, log)
    assert code == 1 and "FAILED" in out, out[-3000:]
    first = submission_id(out)
    states = lambda: {a["state"] for a in train_actors(local_cluster, first)}  # noqa: E731
    eventually(lambda: states() == {"DEAD"}, 30, "the worker of the killed driver ended")

    log = tmp_path / "resumed.log"
    code, out = finish(start_job(local_cluster, submit_argv(local_cluster, cluster_inputs.shards, name, resume=True),
                                 log), log)
    assert code == 0, out[-3000:]
    assert "[sray] resumed at step 4" in out
    [run] = run_ids(local_cluster, name)
    assert psql(local_cluster, f"SELECT status FROM runs WHERE run_uuid = '{run}'") == [["FINISHED"]]
    for key in TRAIN_KEYS:
        assert sorted(set(metric_steps(local_cluster, run, key))) == STEPS, key
