"""The fleet on the local cluster, and many runs writing to its tracking server at once.

``sray finetune-fleet --address`` spreads scene tasks over both worker nodes (each result records its node);
16 processes logging through sray's MLflow logger at the same moment lose no metric (counted in PostgreSQL).
Marked ``cluster``; one cluster per session (``cluster_fixtures.local_cluster``, through conftest.py).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from cluster_fixtures import ClusterInputs, LocalCluster
from cluster_jobs import node_ids, psql
from concurrent_loggers import KEYS

pytestmark = pytest.mark.cluster

TINY_FLEET = {"finetune.max_steps": 6, "finetune.eval_every": 3, "finetune.patience": 2, "finetune.lr": 1e-2,
              "finetune.held_out.n_source": 3, "finetune.held_out.stride": 4, "retries": 1, "retry_backoff_s": 0.1}
"""``--set`` values of a seconds-long scene task (``fleet_fixtures.tiny_fleet_config``)."""
SCENES = ["synth_train_000", "synth_test_000"]
RUNS, STEPS = 16, 40
"""Concurrent logger processes and the steps each logs."""


def test_fleet_spreads_scene_tasks_over_both_worker_nodes(local_cluster: LocalCluster, cluster_inputs: ClusterInputs,
                                                          tmp_path: Path) -> None:
    """Each worker node offers 1 CPU and each task asks for 1 (``--cpus-per-task 1``): the two tasks, in flight
    together (``--max-parallel 2``), can only run one per node. Both results record a different worker node (the
    nodes Ray lists), and each child run in PostgreSQL holds the held-out mIoU of every point of its curve."""
    out = local_cluster.state.storage / "fleet"
    settings = [arg for key, value in TINY_FLEET.items() for arg in ("--set", f"{key}={value}")]
    done = local_cluster.sray("finetune-fleet", "--address", local_cluster.state.ray_address, "--checkpoint",
                              str(cluster_inputs.checkpoint), "--data", str(cluster_inputs.shards), "--scenes", *SCENES,
                              "--tracking-uri", local_cluster.state.tracking_uri, "--out", str(out),
                              "--max-parallel", "2", "--cpus-per-task", "1", *settings, timeout=180)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]

    results = json.loads((out / "fleet_results.json").read_text())
    workers = {node for node, head in node_ids(local_cluster).items() if not head}
    assert [r["scene"] for r in results] == SCENES and all(r["status"] == "finished" for r in results)
    assert {r["node_id"] for r in results} == workers
    for r in results:
        rows = psql(local_cluster, f"SELECT step FROM metrics WHERE run_uuid = '{r['child_run_id']}' "
                                   "AND key = 'heldout/miou' ORDER BY step")
        assert [int(s) for [s] in rows] == [p["step"] for p in r["curve"]]


def test_sixteen_runs_logging_at_once_lose_no_metric(local_cluster: LocalCluster, tmp_path: Path) -> None:
    """16 processes log 40 steps of 4 metrics each through ``MlflowRunLogger`` at the same moment (a fleet's
    children at their busiest): PostgreSQL holds every (run, metric, step) once, with the logged values."""
    script = Path(__file__).resolve().parent / "concurrent_loggers.py"
    done = subprocess.run([sys.executable, str(script), local_cluster.state.tracking_uri, "sray-storm", str(RUNS),
                           str(STEPS)], capture_output=True, text=True, timeout=240, env=local_cluster.env)
    assert done.returncode == 0, done.stderr[-3000:]
    made = json.loads(done.stdout.splitlines()[-1])
    assert made["exit"] == [0] * RUNS

    ids = ", ".join(f"'{run}'" for run in made["runs"])
    rows = psql(local_cluster, "SELECT run_uuid, key, count(*), count(DISTINCT step), min(step), max(step), sum(value) "
                               f"FROM metrics WHERE run_uuid IN ({ids}) GROUP BY run_uuid, key")
    expected = {(run, key): [str(STEPS), str(STEPS), "0", str(STEPS - 1), f"{(k + 1) * STEPS * (STEPS - 1) // 2:g}"]
                for run in made["runs"] for k, key in enumerate(KEYS)}
    assert {(r[0], r[1]): r[2:] for r in rows} == expected
    statuses = psql(local_cluster, f"SELECT status, count(*) FROM runs WHERE run_uuid IN ({ids}) GROUP BY status")
    assert statuses == [["FINISHED", str(RUNS)]]
