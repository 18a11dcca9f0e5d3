"""``sray submit`` on the local cluster, as a user sends a job: it trains on the worker nodes, logs to the
PostgreSQL-backed MLflow server, checkpoints on the shared storage, and ``--wait`` exits with the job's status;
when its driver is killed, ``--resume`` continues it from its checkpoint.

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
MODEL = "sray-cluster"
"""Registered model name of the job."""


def test_submitted_job_killed_driver_then_resume_on_the_worker_nodes(
        local_cluster: LocalCluster, cluster_inputs: ClusterInputs, ray_session: dict, tmp_path: Path) -> None:
    """A 2-worker job is submitted; while rank 0 waits before step 6 (checkpoint at step 4) its driver gets
    SIGKILL: ``--wait`` exits 1 (FAILED) and Ray ends the workers. ``sray submit --resume`` restarts at step 4
    and exits 0. Checked against the cluster's records: both jobs' workers ran one per worker node, none on the
    head (Ray's actor table); one FINISHED MLflow run in PostgreSQL whose history holds every step 1-10; the last
    checkpoint on the shared storage; the registered model's files in the server's proxied artifact store;
    ``sray ui`` on the server links the job's experiment. Another Ray runs on the machine meanwhile (the test
    session's own, ``ray_session``), and the job's log shows no traceback."""
    name, log = "driver-killed", tmp_path / "first.log"
    workers = {node for node, head in node_ids(local_cluster).items() if not head}
    argv = submit_argv(local_cluster, cluster_inputs.shards, name, workers=2, run__register_model=MODEL)
    proc = start_job(local_cluster, argv, log, faults="train.hold_at_steps=6")
    wait_for_hold(job_dir(local_cluster, name), 6, proc, log)
    first = submission_id(log.read_text())
    os.kill(int(dashboard_get(local_cluster, f"/api/jobs/{first}")["driver_info"]["pid"]), signal.SIGKILL)
    code, out = finish(proc, log)
    assert code == 1 and f"job {first} FAILED" in out, out[-3000:]
    actors = lambda: train_actors(local_cluster, first)  # noqa: E731
    eventually(lambda: {a["state"] for a in actors()} == {"DEAD"}, 30, "the workers of the killed driver ended")
    assert {a["node_id"] for a in actors()} == workers

    log = tmp_path / "resumed.log"
    resume = submit_argv(local_cluster, cluster_inputs.shards, name, resume=True)
    code, out = finish(start_job(local_cluster, resume, log), log)
    assert code == 0 and "SUCCEEDED" in out, out[-3000:]
    assert "[sray] resumed at step 4" in out and "Traceback" not in out, out[-3000:]
    finished = f"[sray] finished: best checkpoint {job_dir(local_cluster, name) / 'checkpoints' / 'step_000000010'}"
    assert out.count(finished) == 1, out[-3000:]  # the driver's last line, once: --wait shows the whole log
    assert {a["node_id"] for a in train_actors(local_cluster, submission_id(out))} == workers

    [run] = run_ids(local_cluster, name)
    assert psql(local_cluster, f"SELECT status FROM runs WHERE run_uuid = '{run}'") == [["FINISHED"]]
    for key in TRAIN_KEYS:
        assert sorted(set(metric_steps(local_cluster, run, key))) == STEPS, key
    assert (job_dir(local_cluster, name) / "checkpoints" / "step_000000010" / "state.pt").is_file()
    [[_, run_of_version]] = psql(local_cluster, f"SELECT version, run_id FROM model_versions WHERE name = '{MODEL}'")
    assert run_of_version == run
    uploaded = list((local_cluster.dir / "artifacts").glob(f"*/{run}/artifacts/checkpoint/state.pt"))
    assert len(uploaded) == 1, "the registered checkpoint went through the server's proxied artifact store"
    [[experiment]] = psql(local_cluster, f"SELECT experiment_id FROM runs WHERE run_uuid = '{run}'")
    shown = local_cluster.sray("ui", "--tracking-uri", local_cluster.state.tracking_uri, timeout=60)
    assert shown.returncode == 0 and f"'sray-synth-small': {local_cluster.state.tracking_uri}" in shown.stdout
    assert f"/experiments/{experiment}/" in shown.stdout, shown.stdout
