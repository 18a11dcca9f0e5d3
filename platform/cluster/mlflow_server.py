"""The cluster's MLflow tracking server on 127.0.0.1: PostgreSQL backend store (its password as ``PGPASSWORD``,
never on a command line), artifacts proxied into ``<dir>/artifacts``, Host-header validation allowing only the
loopback names of its port (a request naming another host, DNS rebinding, gets 403)."""

from __future__ import annotations

import os
import sys
import urllib.error
import urllib.request
from pathlib import Path

from sray.platform.cluster.processes import ProcessRecord, spawn
from sray.platform.tracking.dashboard import SERVER_ENV


def healthy(url: str) -> bool:
    """True when ``<url>/health`` answers 200."""
    try:
        with urllib.request.urlopen(f"{url}/health", timeout=2) as reply:
            return reply.status == 200
    except (urllib.error.URLError, ConnectionError, TimeoutError, OSError):
        return False


def spawn_server(backend_uri: str, password: str, artifacts: Path, port: int, log_path: Path) -> ProcessRecord:
    """Start ``mlflow server`` on 127.0.0.1:``port`` without waiting for it (:func:`healthy` says when it answers)."""
    artifacts.mkdir(parents=True, exist_ok=True)
    hosts = ",".join(f"{host}{suffix}" for host in ("127.0.0.1", "localhost") for suffix in ("", f":{port}"))
    cmd = [sys.executable, "-m", "mlflow", "server", "--backend-store-uri", backend_uri,
           "--serve-artifacts", "--artifacts-destination", str(artifacts), "--host", "127.0.0.1",
           "--port", str(port), "--workers", "1", "--allowed-hosts", hosts]
    return spawn(cmd, log_path, env={**os.environ, **SERVER_ENV, "PGPASSWORD": password})

