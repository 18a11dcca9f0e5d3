"""``sray cluster up|status|restart|down`` (docs/cluster.md): PostgreSQL, MLflow and a multi-node Ray on 127.0.0.1;
``up`` starts them in dependency order (a failure stops what it started), ``down`` in reverse, keeping the data."""

from __future__ import annotations

import dataclasses
import json
import os
import secrets
import signal
import time
import urllib.error
import urllib.request
from pathlib import Path

from sray.platform.cluster import mlflow_server, postgres, ray_nodes
from sray.platform.cluster.exposure import exposure_line, listeners
from sray.platform.cluster.processes import ClusterError, ProcessRecord, free_port, port_open, stop, wait_until
from sray.platform.cluster.state import ClusterState, load_state, update_state

STOP_ORDER = ("ray-worker", "ray-head", "mlflow", "postgres")
"""Name prefixes in the order ``down`` stops them: Ray first, the database last."""


def _port(previous: dict[str, int], name: str) -> int:
    """The port ``name`` had last time when it is still free, else a new free one."""
    old = previous.get(name)
    return old if old and not port_open("127.0.0.1", old) else free_port()


def alive_nodes(state: ClusterState) -> int:
    """Alive Ray nodes, asked from the dashboard's state API with the cluster's token (0 if unreachable)."""
    request = urllib.request.Request(f"{state.dashboard_url}/api/v0/nodes?limit=100",
                                     headers={"Authorization": f"Bearer {state.token_path.read_text().strip()}"})
    try:
        with urllib.request.urlopen(request, timeout=5) as reply:
            nodes = json.loads(reply.read())["data"]["result"]["result"]
    except (urllib.error.URLError, OSError, ValueError, KeyError):
        return 0
    return sum(1 for n in nodes if n.get("state") == "ALIVE")


def _new_state(root: Path, workers: int, cpus_per_worker: int) -> ClusterState:
    """A record for a new ``up``: the old password and, where still free, the old ports."""
    old = load_state(root)
    state = ClusterState(dir=str(root), password=old.password if old else secrets.token_urlsafe(24),
                         workers=workers, cpus_per_worker=cpus_per_worker)
    previous = old.ports if old else {}
    state.ports = {name: _port(previous, name) for name in ("postgres", "mlflow", "gcs", "dashboard")}
    return state


def _timed(state: ClusterState, name: str, start: float) -> None:
    state.startup_s[name] = round(time.monotonic() - start, 1)


def _started(state: ClusterState, name: str, record: ProcessRecord) -> None:
    """Record process ``name`` on disk (under the record's lock) and in ``state``."""
    entry = dataclasses.asdict(record)
    state.processes = update_state(state.root, lambda on_disk: on_disk.processes.update({name: entry})).processes


def _stop(name: str, record: ProcessRecord) -> bool:
    """Stop part ``name``: PostgreSQL by SIGINT, its fast shutdown (SIGTERM waits for every client to leave)."""
    sig = signal.SIGINT if name == "postgres" else signal.SIGTERM
    return stop(record, sig=sig, supervisor=name.startswith("ray-"))


def _start_part(state: ClusterState, name: str, wait: bool = True) -> None:
    """Start part ``name`` (``postgres``, ``mlflow``, ``ray-head``, ``ray-worker-<i>``), record it and time it.
    ``wait=False`` leaves the MLflow server starting (:func:`_mlflow_ready` waits and times it)."""
    root, logs, t0 = state.root, state.root / "logs", time.monotonic()
    if name == "postgres":
        bins = postgres.ensure_installed(logs / "apt.log")
        postgres.init_db(bins, root / "pg", state.password, logs / "initdb.log")
        _started(state, name, postgres.start(bins, root / "pg", state.ports["postgres"], logs / "postgres.log"))
        postgres.ensure_database(bins, state.ports["postgres"], state.password)
    elif name == "mlflow":
        _started(state, name, mlflow_server.spawn_server(postgres.backend_uri(state.ports["postgres"]), state.password,
                                                         root / "artifacts", state.ports["mlflow"],
                                                         logs / "mlflow.log"))
        if not wait:
            return
        _mlflow_ready(state)
    elif name == "ray-head":
        _started(state, name, ray_nodes.start_head(root / "ray" / "head", state.ports["gcs"], state.ports["dashboard"],
                                                   state.token_path, logs / "ray-head.log"))
    elif name.startswith("ray-worker-") and name.removeprefix("ray-worker-").isdigit():
        i = name.removeprefix("ray-worker-")
        _started(state, name, ray_nodes.start_worker(state.ray_address, root / "ray" / f"w{i}", state.cpus_per_worker,
                                                     state.token_path, logs / f"{name}.log"))
    else:
        raise ClusterError(f"no part {name!r}; parts: postgres, mlflow, ray-head, ray-worker-1 ... "
                           f"ray-worker-{state.workers}")
    _timed(state, name, t0)


def _mlflow_ready(state: ClusterState) -> None:
    """Wait for the recorded MLflow server to answer ``/health``; ClusterError naming its log otherwise."""
    wait_until(lambda: mlflow_server.healthy(state.tracking_uri), 120.0, "the MLflow server",
               state.root / "logs" / "mlflow.log", state.record("mlflow"))


def _wait_nodes(state: ClusterState, timeout_s: float = 120.0) -> None:
    """Wait until the head and every recorded worker node are alive in Ray."""
    expected = 1 + sum(1 for n in state.processes if n.startswith("ray-worker-"))
    wait_until(lambda: alive_nodes(state) >= expected, timeout_s, f"{expected - 1} Ray worker node(s)",
               state.root / "logs" / "ray-worker-1.log")


def up(root: Path, workers: int = 2, cpus_per_worker: int = 1) -> ClusterState:
    """Start the cluster in ``root`` (created if needed); ClusterError when it runs already or a part fails."""
    root = Path(root).resolve()
    current = load_state(root)
    if current is not None and any(current.alive().values()):
        raise ClusterError(f"a cluster runs from {root} already (`sray cluster status --dir {root}`); "
                           f"stop it with `sray cluster down --dir {root}` first")
    if workers < 1 or cpus_per_worker < 1:
        raise ClusterError(f"--workers and --cpus-per-worker must be at least 1, got {workers} and {cpus_per_worker}")
    for sub in ("logs", "ray", "shared", "artifacts"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    if os.geteuid() == 0:
        root.chmod(0o755)  # PostgreSQL runs as its own user and must reach <dir>/pg
    state = _new_state(root, workers, cpus_per_worker)
    if not state.token_path.exists():
        state.token_path.write_text(secrets.token_hex(32) + "\n")
        state.token_path.chmod(0o600)
    state.save()
    try:
        _start_part(state, "postgres")
        t_mlflow = time.monotonic()
        _start_part(state, "mlflow", wait=False)  # the server imports MLflow while the Ray nodes start
        for name in ("ray-head", *(f"ray-worker-{i}" for i in range(1, workers + 1))):
            _start_part(state, name)
        _mlflow_ready(state)
        _timed(state, "mlflow", t_mlflow)
        t0 = time.monotonic()
        _wait_nodes(state)
        _timed(state, "ray-workers-joined", t0)
    except BaseException:
        down(root)
        raise
    state.save()
    return state


def restart(root: Path, name: str, outage_s: float = 0.0) -> ClusterState:
    """Stop part ``name`` if it runs, wait ``outage_s`` seconds, start it again; returns the updated record."""
    state = status(root)
    record = state.record(name)
    if record is not None:
        _stop(name, record)
    time.sleep(outage_s)
    t0 = time.monotonic()
    _start_part(state, name)
    if name.startswith("ray-worker-"):
        _wait_nodes(state)
        _timed(state, name, t0)  # a worker node is ready once Ray lists it, not when its process exists
    took = state.startup_s[name]
    return update_state(state.root, lambda on_disk: on_disk.startup_s.update({name: took}))


def status(root: Path) -> ClusterState:
    """The cluster's record; ClusterError when ``root`` holds none."""
    state = load_state(Path(root).resolve())
    if state is None:
        raise ClusterError(f"{Path(root).resolve()}: no cluster here; start one with `sray cluster up --dir {root}`")
    return state


def down(root: Path) -> list[str]:
    """Stop the recorded processes (Ray, then MLflow, then PostgreSQL); returns the names that were running."""
    state = load_state(Path(root).resolve())
    if state is None:
        return []
    stopped = []
    for prefix in STOP_ORDER:
        for name in sorted(n for n in state.processes if n.startswith(prefix)):
            if _stop(name, ProcessRecord(**state.processes[name])):
                stopped.append(name)
    update_state(state.root, lambda on_disk: on_disk.processes.clear())
    return stopped


def describe(state: ClusterState) -> str:
    """What ``sray cluster up|status|restart`` print: processes, addresses, the clients' token, non-loopback ports."""
    alive = state.alive()
    running = ", ".join(f"{n} {'up' if ok else 'DOWN'} (pid {state.processes[n]['pid']})" for n, ok in alive.items())
    env = " ".join(f"{k}={v}" for k, v in ray_nodes.auth_env(state.token_path).items())
    return "\n".join([
        f"[cluster] processes: {running or 'none running'}",
        f"[cluster] Ray address:     --address {state.ray_address}   (sray train / finetune-fleet)",
        f"[cluster] Jobs API:        --address {state.dashboard_url}   (sray submit; Ray dashboard)",
        f"[cluster] tracking URI:    --tracking-uri {state.tracking_uri}   (MLflow UI there too)",
        f"[cluster] shared storage:  --set run.output_dir={state.storage / 'jobs'}",
        f"[cluster] clients need the Ray token:  export {env}",
        exposure_line(listeners({n: state.processes[n]["pid"] for n, ok in alive.items() if ok})),
    ])
