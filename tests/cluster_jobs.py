"""What the cluster tests do to a local cluster and what they read back from it.

Tiny training jobs go through ``sray submit --wait`` as a user would (:func:`start_job`); faults
stop them at a known step through the fault hook's pauses (``train.hold_at_steps``,
:func:`wait_for_hold` / :func:`release`). The facts the tests compare against come from the
cluster's own records, not from sray: PostgreSQL rows through ``psql`` (:func:`psql`,
:func:`metric_steps`) and Ray's actor table through the dashboard's state API (:func:`train_actors`).
"""

from __future__ import annotations

import json
import os
import subprocess
import time
import urllib.parse
import urllib.request
from collections.abc import Callable
from pathlib import Path

from cluster_fixtures import SRAY, LocalCluster

TINY_TRAIN = {"model.n_source": 3, "model.n_coarse": 8, "model.n_fine": 8, "runtime.chunk": 1024, "data.top_k": 4,
              "data.rays_per_batch": 64, "data.loader_workers": 0, "data.val_views_per_scene": 1,
              "data.held_out.stride": 2, "optim.steps": 10, "optim.lr": 3e-3, "optim.lr_final": 1e-3,
              "run.log_every": 1, "run.val_every": 10, "run.ckpt_every": 4, "run.register_model": ""}
"""``--set`` values of a seconds-long job (the network of ``train_fixtures.tiny_config``): 10 steps, every
step logged, checkpoints at steps 4, 8 and 10, validation at the end, no model registration."""
TRAIN_KEYS = ("train/loss", "train/lr", "train/grad_norm")
"""Metrics rank 0 logs at every step (``run.log_every=1``), among others."""


def job_dir(cluster: LocalCluster, name: str) -> Path:
    """Folder of job ``name`` on the cluster's shared storage."""
    return cluster.state.storage / "jobs" / name


def submit_argv(cluster: LocalCluster, shards: Path, name: str, workers: int = 1, resume: bool = False,
                **settings: object) -> list[str]:
    """``sray submit --wait ...`` of a tiny job called ``name`` (``settings``: more ``--set`` values, dotted keys
    written with ``__``)."""
    argv = [*SRAY, "submit", "--wait", "--address", cluster.state.dashboard_url,
            "--set", f"run.output_dir={cluster.state.storage / 'jobs'}"]
    if resume:
        return [*argv, "--resume", name]
    argv += ["--data", str(shards), "--tracking-uri", cluster.state.tracking_uri, "--name", name,
             "--workers", str(workers)]
    for key, value in (TINY_TRAIN | {k.replace("__", "."): v for k, v in settings.items()}).items():
        argv += ["--set", f"{key}={value}"]
    return argv


def start_job(cluster: LocalCluster, argv: list[str], log: Path, faults: str = "") -> subprocess.Popen:
    """Run ``argv`` (a ``sray submit --wait``) in the background with ``SRAY_FAULTS=faults``; output to ``log``."""
    env = {k: v for k, v in cluster.env.items() if k != "SRAY_FAULTS"} | ({"SRAY_FAULTS": faults} if faults else {})
    with open(log, "w") as out:
        return subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT, env=env, cwd=cluster.dir)


def finish(proc: subprocess.Popen, log: Path, timeout: float = 120) -> tuple[int, str]:
    """Wait for a background ``sray submit --wait``; its exit status and output."""
    try:
        code = proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=10)
        raise AssertionError(f"sray submit did not end within {timeout:.0f} s:\n{log.read_text()[-3000:]}") from None
    return code, log.read_text()


def wait_for_hold(folder: Path, step: int, proc: subprocess.Popen, log: Path, timeout: float = 90) -> dict:
    """The marker rank 0 writes when it pauses before ``step`` (``pid``, ``node_id``); fails when the job
    ended first or ``timeout`` passed."""
    from sray.platform.common.fault_hook import hold_paths

    marker = hold_paths(folder, step)[0]
    deadline = time.monotonic() + timeout
    while not marker.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            raise AssertionError(f"no pause at step {step} (exit {proc.poll()}):\n{log.read_text()[-3000:]}")
        time.sleep(0.2)
    return json.loads(marker.read_text())


def eventually(check: Callable[[], bool], timeout: float, what: str) -> None:
    """Poll ``check`` until True; fails naming ``what`` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < deadline, f"not within {timeout:.0f} s: {what}"
        time.sleep(0.5)


def release(folder: Path, step: int) -> None:
    """Let rank 0 go on from its pause before ``step``."""
    from sray.platform.common.fault_hook import hold_paths

    hold_paths(folder, step)[1].touch()


def psql(cluster: LocalCluster, sql: str) -> list[list[str]]:
    """Rows of ``sql`` run by ``psql`` on the cluster's MLflow database, as lists of strings."""
    from sray.platform.cluster.postgres import DB_NAME, DB_USER, bin_dir

    env = {**os.environ, "PGPASSWORD": cluster.state.password}
    done = subprocess.run([str(bin_dir() / "psql"), "-h", "127.0.0.1", "-p", str(cluster.state.ports["postgres"]),
                           "-U", DB_USER, "-d", DB_NAME, "-tA", "-F", "|", "-v", "ON_ERROR_STOP=1", "-c", sql],
                          capture_output=True, text=True, env=env, timeout=30, check=False)
    assert done.returncode == 0, done.stderr
    return [line.split("|") for line in done.stdout.splitlines() if line]


def run_ids(cluster: LocalCluster, name: str) -> list[str]:
    """Ids of the MLflow runs called ``name`` (any experiment), from the database."""
    assert "'" not in name
    return [row[0] for row in psql(cluster, f"SELECT run_uuid FROM runs WHERE name = '{name}'")]


def metric_steps(cluster: LocalCluster, run_id: str, key: str) -> list[int]:
    """Every step of metric ``key`` stored for ``run_id`` (one entry per row, sorted)."""
    rows = psql(cluster, f"SELECT step FROM metrics WHERE run_uuid = '{run_id}' AND key = '{key}' ORDER BY step")
    return [int(r[0]) for r in rows]


def dashboard_get(cluster: LocalCluster, path: str) -> dict:
    """A JSON answer of the Ray dashboard (with the cluster's token)."""
    token = cluster.state.token_path.read_text().strip()
    request = urllib.request.Request(f"{cluster.state.dashboard_url}{path}",
                                     headers={"Authorization": f"Bearer {token}"})
    with urllib.request.urlopen(request, timeout=20) as reply:
        return json.loads(reply.read())


def node_ids(cluster: LocalCluster) -> dict[str, bool]:
    """Node id -> is the head, for every alive Ray node."""
    nodes = dashboard_get(cluster, "/api/v0/nodes?limit=100&detail=1")["data"]["result"]["result"]
    return {n["node_id"]: bool(n["is_head_node"]) for n in nodes if n["state"] == "ALIVE"}


def train_actors(cluster: LocalCluster, submission_id: str) -> list[dict]:
    """Ray Train's worker actors of a submitted job (``node_id``, ``state``, ``pid``), from Ray's actor table."""
    job = dashboard_get(cluster, f"/api/jobs/{urllib.parse.quote(submission_id)}")
    query = urllib.parse.urlencode({"limit": 1000, "detail": 1, "filter_keys": "class_name",
                                    "filter_predicates": "=", "filter_values": "RayTrainWorker"})
    actors = dashboard_get(cluster, f"/api/v0/actors?{query}")["data"]["result"]["result"]
    return [a for a in actors if a["job_id"] == job["job_id"]]


def submission_id(output: str) -> str:
    """The Jobs API id ``sray submit`` printed (``[sray] submitted <id>: job <name>``)."""
    line = next(x for x in output.splitlines() if x.startswith("[sray] submitted "))
    return line.removeprefix("[sray] submitted ").split(":", 1)[0]


def worker_node_of(cluster: LocalCluster, pid: int) -> str:
    """The cluster part (``ray-worker-<i>``) whose process tree holds ``pid`` (its parents lead to it)."""
    recorded = {entry["pid"]: name for name, entry in cluster.state.processes.items()}
    while pid > 1:
        if pid in recorded:
            return recorded[pid]
        stat = Path(f"/proc/{pid}/stat").read_text()
        pid = int(stat[stat.rindex(")") + 2:].split()[1])
    raise AssertionError("the process is not under any node the cluster started")
