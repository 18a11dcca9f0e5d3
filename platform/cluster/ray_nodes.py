"""Ray nodes of a local cluster: a head (GCS, dashboard, Jobs API; no CPUs) and worker nodes, each a ``ray start
--block`` process with its own temp dir, ports and resources, whose SIGTERM stops that node only. Every node and
client uses the cluster's token (``RAY_AUTH_MODE=token``, ``RAY_AUTH_TOKEN_PATH``): one without it is refused."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from sray.platform.cluster.processes import ProcessRecord, free_port, port_open, spawn, wait_until
from sray.platform.common.ray_env import TRAIN_POLL_ENV

NODE_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_GRACEFUL_SHUTDOWN_DRAIN_TIMEOUT_S": "0"}
"""Environment of every node: no usage stats, no drain wait on SIGTERM."""
OBJECT_STORE_BYTES = 100 * 2**20  # object store per node (the jobs move small tensors; Ray's minimum is 75 MiB)
WORKER_RESOURCE = "sray_worker_node"
"""Custom resource each worker node offers once, so a task can ask for a node of its own."""


def auth_env(token_path: Path) -> dict[str, str]:
    """What a client (``sray submit``, ``sray train --address``) needs in its environment to be let in."""
    return {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN_PATH": str(token_path)}


def _ray() -> str:
    """The ``ray`` script of this Python environment."""
    beside = Path(sys.executable).with_name("ray")
    return str(beside) if beside.exists() else (shutil.which("ray") or "ray")


def _node_env(token_path: Path, gcs_address: str) -> dict[str, str]:
    """A node's environment: ours, the token, this environment's scripts first on PATH (jobs run the cluster's
    installation), jobs' worker polling (:mod:`sray.platform.common.ray_env`) unless ours sets it, and ``RAY_ADDRESS``
    naming this cluster (Ray's actors look up ``address="auto"``, which fails while another Ray runs here)."""
    env = {**TRAIN_POLL_ENV, **os.environ, **NODE_ENV, **auth_env(token_path), "RAY_ADDRESS": gcs_address}
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    return env


def start_head(temp_dir: Path, gcs_port: int, dashboard_port: int, token_path: Path,
               log_path: Path, timeout_s: float = 120.0) -> ProcessRecord:
    """Start the head node (no CPUs; dashboard and Jobs API on 127.0.0.1) and wait for its dashboard."""
    cmd = [_ray(), "start", "--head", "--block", "--node-ip-address", "127.0.0.1", "--port", str(gcs_port),
           "--dashboard-host", "127.0.0.1", "--dashboard-port", str(dashboard_port), "--include-dashboard", "true",
           "--num-cpus", "0", "--num-gpus", "0", "--temp-dir", str(temp_dir),
           "--ray-client-server-port", str(free_port()), "--dashboard-agent-listen-port", str(free_port()),
           "--object-store-memory", str(OBJECT_STORE_BYTES), "--disable-usage-stats"]
    record = spawn(cmd, log_path, env=_node_env(token_path, f"127.0.0.1:{gcs_port}"))
    wait_until(lambda: port_open("127.0.0.1", dashboard_port), timeout_s, "the Ray head", log_path, record)
    return record


def start_worker(gcs_address: str, temp_dir: Path, cpus: int, token_path: Path, log_path: Path) -> ProcessRecord:
    """Start a worker node with ``cpus`` CPUs joining the head at ``gcs_address`` (returns at once)."""
    cmd = [_ray(), "start", "--address", gcs_address, "--block", "--node-ip-address", "127.0.0.1",
           "--num-cpus", str(cpus), "--num-gpus", "0", "--resources", f'{{"{WORKER_RESOURCE}": 1}}',
           "--temp-dir", str(temp_dir), "--dashboard-agent-listen-port", str(free_port()),
           "--object-store-memory", str(OBJECT_STORE_BYTES), "--disable-usage-stats"]
    return spawn(cmd, log_path, env=_node_env(token_path, gcs_address))
