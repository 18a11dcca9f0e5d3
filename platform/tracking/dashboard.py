"""``sray ui``: a lean ``mlflow server`` on localhost (no job runner, one worker: 2 processes, not 15-27)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from importlib.metadata import distributions
from pathlib import Path

from sray.platform.tracking.runs import (DEFAULT_UI_PORT, artifact_root, default_tracking_uri, is_server, probe_server,
                                        sqlite_path)

SERVER_ENV = {"MLFLOW_SERVER_ENABLE_JOB_EXECUTION": "false", "MLFLOW_DISABLE_TELEMETRY": "true",
              "DO_NOT_TRACK": "true", "MLFLOW_ENABLE_AI_GATEWAY": "false"}
"""Environment of the server process: no job runner, no telemetry, no AI Gateway (endpoints and UI)."""
UI_APP = "sray-ui"
"""The server app (``mlflow server --app-name``, entry point group ``mlflow.app``): :mod:`~.ui_app`."""
SORT_BY_RUN_NAME = "orderByKey=tags.%60mlflow.runName%60&orderByAsc=true"
"""Runs-table query sorting by run name: the UI then lists child runs as rows of their own, not folded."""


def runs_view_url(base_url: str, experiment_id: str, flat: bool = False) -> str:
    """Address of an experiment's runs table; ``flat``: sorted by run name, child runs beside their parents."""
    url = f"{base_url.rstrip('/')}/#/experiments/{experiment_id}/runs?workflowType=machine_learning"
    return f"{url}&{SORT_BY_RUN_NAME}" if flat else url


def tunnel_hint(port: int) -> str:
    """How to reach a dashboard on a remote machine: an SSH tunnel from the laptop."""
    return (f"on a remote machine? on your laptop run  ssh -N -L {port}:127.0.0.1:{port} "
            f"USER@{socket.gethostname()}  and open the same address there")


def experiment_links(tracking_uri: str, base_url: str) -> dict[str, str]:
    """Experiment name -> runs-view address, for experiments that hold runs, newest activity first."""
    from mlflow import MlflowClient

    client = MlflowClient(tracking_uri=tracking_uri)
    newest: list[tuple[int, str, str]] = []
    for exp in client.search_experiments():
        runs = client.search_runs([exp.experiment_id], order_by=["attributes.start_time DESC"], max_results=1)
        if runs:
            newest.append((int(runs[0].info.start_time or 0), exp.name, exp.experiment_id))
    return {name: runs_view_url(base_url, exp_id) for _, name, exp_id in sorted(newest, reverse=True)}


@dataclass
class DashboardHandle:
    """A running dashboard server (from :func:`start_dashboard`)."""

    process: subprocess.Popen
    """The ``mlflow server`` process (leader of its own process group)."""
    base_url: str
    url: str
    """Runs view of the experiment with the newest run (``base_url`` when there is none)."""
    log_path: Path
    experiment_urls: dict[str, str] = field(default_factory=dict)
    """Experiment name -> runs-view address, newest activity first."""

    def log_tail(self, n_chars: int = 2000) -> str:
        """The end of the server's log."""
        try:
            return self.log_path.read_text(errors="replace")[-n_chars:]
        except OSError:
            return ""

    def stop(self, timeout_s: float = 15.0) -> int | None:
        """Stop the server and its worker (SIGTERM to its process group, SIGKILL after ``timeout_s``)."""
        for sig in (signal.SIGTERM, signal.SIGKILL):
            if self.process.poll() is not None:
                break
            try:
                os.killpg(self.process.pid, sig)
                self.process.wait(timeout_s)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                continue
        return self.process.poll()

    def __enter__(self) -> DashboardHandle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _check_port_free(host: str, port: int) -> None:
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as e:
            raise OSError(f"cannot listen on {host}:{port} ({e.strerror}); another dashboard may be running "
                          f"there: open it, or pass --port with a free port") from None


def server_links(tracking_uri: str) -> dict[str, str]:
    """A tracking server's own runs views by experiment name; ConnectionError naming the URI when it does not answer."""
    probe_server(tracking_uri)
    return experiment_links(tracking_uri, tracking_uri)


def _resolve_store(tracking_uri: str | None) -> str:
    uri = tracking_uri or default_tracking_uri(Path.cwd())
    if is_server(uri):
        raise ValueError(f"{uri} is a tracking server, which serves its own dashboard: open "
                         f"{runs_view_url(uri, '<experiment id>')} instead of starting another")
    db = sqlite_path(uri)
    if db is None:
        return uri
    if not db.is_file():
        raise FileNotFoundError(f"{db}: no MLflow store there; run a job first (sray train / eval / "
                                "finetune-fleet log into the working directory's store) or pass --tracking-uri")
    return f"sqlite:///{db}"


def _ui_app_installed() -> bool:
    """True when a distribution offers :data:`UI_APP` (read all: a stale ``sray.egg-info`` hides it from one)."""
    return any(ep.group == "mlflow.app" and ep.name == UI_APP for dist in distributions() for ep in dist.entry_points)


def _wait_ready(handle: DashboardHandle, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if handle.process.poll() is not None:
            raise RuntimeError(f"mlflow server exited with code {handle.process.returncode} before answering; its log "
                               f"({handle.log_path}) ends with:\n{handle.log_tail()}")
        try:
            with urllib.request.urlopen(f"{handle.base_url}/health", timeout=2) as reply:
                if reply.status == 200:
                    return
        except (urllib.error.URLError, ConnectionError, TimeoutError):
            pass
        time.sleep(0.3)
    raise TimeoutError(f"mlflow server did not answer at {handle.base_url}/health within {timeout_s:.0f} s; "
                       f"see its log {handle.log_path}")


def start_dashboard(tracking_uri: str | None = None, port: int = DEFAULT_UI_PORT, host: str = "127.0.0.1",
                    *, timeout_s: float = 120.0) -> DashboardHandle:
    """Start the dashboard on ``tracking_uri`` (default: the working directory's SQLite store); its handle once it
    answers. FileNotFoundError (no store), ValueError (a server), OSError (port taken), RuntimeError/TimeoutError."""
    uri = _resolve_store(tracking_uri)  # absolute: the server runs outside the working directory (see below)
    _check_port_free(host, port)
    if not _ui_app_installed():
        raise RuntimeError(f"the MLflow server app {UI_APP!r} is not installed; reinstall sray "
                           "(make setup, or pip install -e . in the repository)")
    cmd = [sys.executable, "-m", "mlflow", "server", "--backend-store-uri", uri, "--host", host,
           "--port", str(port), "--workers", "1", "--app-name", UI_APP]
    destination = artifact_root(uri)
    if destination is not None:
        destination.mkdir(parents=True, exist_ok=True)
        cmd += ["--artifacts-destination", str(destination)]
    log_path = Path(tempfile.mkstemp(prefix=f"sray-ui-{port}-", suffix=".log")[1])
    # run in the log's folder: a stale sray.egg-info in the working directory would hide the --app-name entry point
    with open(log_path, "wb") as log_file:
        proc = subprocess.Popen(cmd, stdout=log_file, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                env={**os.environ, **SERVER_ENV}, cwd=log_path.parent, start_new_session=True)
    url_host = f"[{host}]" if ":" in host else host
    base_url = f"http://{url_host}:{port}"
    handle = DashboardHandle(process=proc, base_url=base_url, url=base_url + "/", log_path=log_path)
    try:
        _wait_ready(handle, timeout_s)
        handle.experiment_urls = experiment_links(uri, base_url)
    except BaseException:
        handle.stop()
        raise
    if handle.experiment_urls:
        handle.url = next(iter(handle.experiment_urls.values()))
    return handle
