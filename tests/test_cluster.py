"""``sray cluster``: PostgreSQL + MLflow server + Ray head and 2 worker nodes as real processes.

Marked ``cluster`` (select with ``-m cluster``); skipped with the reason where PostgreSQL cannot
be installed. One cluster serves the whole session (``cluster_fixtures.local_cluster``, through conftest.py).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cluster_fixtures import ClusterInputs, LocalCluster  # noqa: E402

pytestmark = pytest.mark.cluster


def _status(url: str, headers: dict[str, str]) -> int:
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers), timeout=10) as reply:
            return reply.status
    except urllib.error.HTTPError as e:
        return e.code


def test_cluster_up_status_and_the_parts_it_started(local_cluster: LocalCluster) -> None:
    """Every recorded process runs, 3 Ray nodes are alive, status prints the addresses to pass on."""
    from sray.platform.cluster.local_cluster import alive_nodes

    state = local_cluster.state
    assert all(state.alive().values()) and set(state.processes) == {
        "postgres", "mlflow", "ray-head", "ray-worker-1", "ray-worker-2"}
    assert alive_nodes(state) == 3
    shown = local_cluster.sray("cluster", "status", "--dir", str(local_cluster.dir))
    assert shown.returncode == 0, shown.stderr
    for text in (f"--address {state.ray_address}", f"--address {state.dashboard_url}",
                 f"--tracking-uri {state.tracking_uri}", "RAY_AUTH_MODE=token"):
        assert text in shown.stdout
    with urllib.request.urlopen(f"{state.tracking_uri}/api/2.0/mlflow/experiments/search?max_results=5",
                                timeout=10) as reply:
        assert "experiments" in json.loads(reply.read())
    assert oct((local_cluster.dir / "cluster.json").stat().st_mode & 0o777) == "0o600"


def test_status_reports_the_ports_that_listen_beyond_loopback(local_cluster: LocalCluster) -> None:
    """The exposure report agrees with the kernel's socket table as ``ss`` prints it: PostgreSQL, MLflow and
    the dashboard on 127.0.0.1 only; whatever listens on a wildcard address (Ray's GCS) is named."""
    from sray.platform.cluster.exposure import listeners

    state = local_cluster.state
    found = listeners({n: r["pid"] for n, r in state.processes.items()})
    ss = subprocess.run(["ss", "-ltnpH"], capture_output=True, text=True, check=True).stdout.splitlines()
    pids = {x.pid for x in found}
    seen = set()
    for row in ss:
        pid = next((p for p in pids if f"pid={p}," in row), None)
        if pid is not None:
            local, port = row.split()[3].rsplit(":", 1)
            seen.add((pid, int(port), local.strip("[]") in ("127.0.0.1", "::1", "::ffff:127.0.0.1")))
    assert {(x.pid, x.port, x.loopback_only) for x in found} == seen
    for name in ("postgres", "mlflow", "dashboard"):
        bound = [x for x in found if x.port == state.ports[name]]
        assert bound and all(x.loopback_only for x in bound), bound
    shown = local_cluster.sray("cluster", "status", "--dir", str(local_cluster.dir)).stdout
    open_ = [x for x in found if not x.loopback_only]
    assert all(f"{x.address}:{x.port}" in shown for x in open_)
    assert ("beyond loopback" in shown) == bool(open_)


def test_refused_without_the_ray_token_or_with_a_foreign_host_header(local_cluster: LocalCluster) -> None:
    """The Jobs API answers 401 without the token; MLflow answers 403 to an unknown Host header."""
    state = local_cluster.state
    token = state.token_path.read_text().strip()
    jobs = f"{state.dashboard_url}/api/jobs/"
    assert _status(jobs, {}) == 401
    assert _status(jobs, {"Authorization": "Bearer not-the-token"}) in (401, 403)
    assert _status(jobs, {"Authorization": f"Bearer {token}"}) == 200
    search = f"{state.tracking_uri}/api/2.0/mlflow/experiments/search?max_results=1"
    assert _status(search, {"Host": "rebind.example.com"}) == 403
    assert _status(search, {}) == 200
    env = {k: v for k, v in local_cluster.env.items() if not k.startswith("RAY_AUTH")}
    env |= {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": "0" * 64,
            "RAY_gcs_server_port_wait_time_s": "1"}  # one attempt, not Ray's 20 s of retries
    probe = "import ray; ray.init(address='%s'); print('joined')" % state.ray_address
    joined = local_cluster.python(probe, env=env, timeout=60)
    assert "joined" not in joined.stdout and "InvalidAuthToken" in joined.stderr, joined.stderr[-2000:]


def test_sray_refuses_a_cluster_address_without_its_token_in_one_line(local_cluster: LocalCluster,
                                                                       cluster_inputs: ClusterInputs,
                                                                       tmp_path: Path) -> None:
    """``sray train`` and ``sray finetune-fleet --address`` without the token: exit 2 with one line naming the
    token variables, before anything is written (Ray itself retries for 20 s, then prints a traceback)."""
    env = {k: v for k, v in local_cluster.env.items() if not k.startswith("RAY_AUTH")}
    address = local_cluster.state.ray_address
    for argv in (["train", "--data", str(cluster_inputs.shards), "--set", f"run.output_dir={tmp_path / 'jobs'}"],
                 ["finetune-fleet", "--checkpoint", str(cluster_inputs.checkpoint), "--data",
                  str(cluster_inputs.shards), "--all-test", "--out", str(tmp_path / "fleet")]):
        t0 = time.monotonic()
        done = local_cluster.sray(*argv, "--address", address, "--tracking-uri", f"sqlite:///{tmp_path / 'm.db'}",
                                  env=env, timeout=60, cwd=tmp_path)
        took = time.monotonic() - t0
        lines = [line for line in done.stderr.splitlines() if line.strip()]
        assert done.returncode == 2 and len(lines) == 1, done.stdout[-2000:] + done.stderr[-2000:]
        assert f"--address {address}: the Ray cluster refused this client's token" in lines[0]
        assert "RAY_AUTH_TOKEN_PATH" in lines[0] and took < 15, (lines, took)
    assert not (tmp_path / "jobs").exists() and not (tmp_path / "fleet").exists() and not (tmp_path / "m.db").exists()
