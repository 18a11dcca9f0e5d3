"""``sray ui`` stopped by SIGTERM (``kill``) or SIGHUP (a closed terminal) stops its MLflow server too."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: E402,F401  (pytest fixtures, used by name)


def _descendants(pid: int) -> set[int]:
    """Every live descendant of ``pid`` (read from /proc)."""
    found, todo = set(), [pid]
    while todo:
        parent = todo.pop()
        try:
            children = Path(f"/proc/{parent}/task/{parent}/children").read_text().split()
        except OSError:
            continue
        for child in map(int, children):
            found.add(child)
            todo.append(child)
    return found


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_ui_stops_its_server_on_sigterm_and_sighup(mlflow_uri: str, signum: int) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    ui = subprocess.Popen([sys.executable, "-m", "sray.jobs.cli", "ui", "--tracking-uri", mlflow_uri,
                           "--port", str(port)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        for line in ui.stdout:
            if "MLflow dashboard:" in line or time.monotonic() > deadline:
                break
        server = _descendants(ui.pid)
        assert server, "sray ui started no server process"
        ui.send_signal(signum)
        assert ui.wait(timeout=30) == 0, ui.stdout.read()
        deadline = time.monotonic() + 10
        while any(_alive(p) for p in server) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not [p for p in server if _alive(p)], f"left after {signal.Signals(signum).name}: {ui.stdout.read()}"
        with pytest.raises(OSError):
            socket.create_connection(("127.0.0.1", port), timeout=2).close()
    finally:
        if ui.poll() is None:
            ui.kill()
            ui.wait()
        for pid in _descendants(ui.pid):
            os.kill(pid, signal.SIGKILL)
