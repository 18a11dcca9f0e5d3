"""The cluster's MLflow tracking server: PostgreSQL backend store, proxied artifacts, loopback only.

The database password reaches the server as ``PGPASSWORD`` (never on a command line ``ps`` shows).
Artifacts are proxied (``--serve-artifacts``) into ``<dir>/artifacts``: clients upload through the
server and need no access to the folder. Host-header validation stays on, with only the loopback
names of this port allowed, so a request naming another host (DNS rebinding) gets 403.
"""

from __future__ import annotations

import os
import sys
import urllib.error
import urllib.request
from pathlib import Path

from sray.platform.cluster.processes import ProcessRecord, spawn, wait_until
from sray.platform.tracking.dashboard import SERVER_ENV


def allowed_hosts(port: int) -> str:
    """The Host headers the server accepts: the loopback names, with and without the port."""
    return ",".join(f"{host}{suffix}" for host in ("127.0.0.1", "localhost") for suffix in ("", f":{port}"))


def healthy(url: str) -> bool:
    """True when ``<url>/health`` answers 200."""
    try:
        with urllib.request.urlopen(f"{url}/health", timeout=2) as reply:
            return reply.status == 200
    except (urllib.error.URLError, ConnectionError, TimeoutError, OSError):
        return False


def spawn_server(backend_uri: str, password: str, artifacts: Path, port: int, log_path: Path) -> ProcessRecord:
    """Start ``mlflow server`` on 127.0.0.1:``port`` without waiting for it (:func:`wait_ready`)."""
    artifacts.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "mlflow", "server", "--backend-store-uri", backend_uri,
           "--serve-artifacts", "--artifacts-destination", str(artifacts), "--host", "127.0.0.1",
           "--port", str(port), "--workers", "1", "--allowed-hosts", allowed_hosts(port)]
    env = {**os.environ, **SERVER_ENV, "PGPASSWORD": password}
    return spawn(cmd, log_path, env=env)


def wait_ready(record: ProcessRecord, port: int, log_path: Path, timeout_s: float = 120.0) -> None:
    """Wait until the server of ``record`` answers ``/health``; ClusterError naming ``log_path`` otherwise."""
    wait_until(lambda: healthy(f"http://127.0.0.1:{port}"), timeout_s, "the MLflow server", log_path, record)


def start(backend_uri: str, password: str, artifacts: Path, port: int, log_path: Path,
          timeout_s: float = 120.0) -> ProcessRecord:
    """Start ``mlflow server`` on 127.0.0.1:``port`` and wait for ``/health``."""
    record = spawn_server(backend_uri, password, artifacts, port, log_path)
    wait_ready(record, port, log_path, timeout_s)
    return record
