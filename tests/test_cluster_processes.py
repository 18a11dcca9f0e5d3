"""Stopping a recorded process group: a supervisor that outlives the processes it watches (as ``ray start
--block`` sometimes does after SIGTERM) is killed once they have ended, not waited on for the timeout."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from sray.platform.cluster.processes import group_members, is_alive, spawn, stop

SUPERVISOR = """
import signal, subprocess, sys, time
signal.signal(signal.SIGTERM, lambda *_: None)  # ignores the stop request, like a stuck supervisor
child = subprocess.Popen(["sleep", "300"])       # same group; never reaped: a zombie once it ends
print(child.pid, flush=True)
time.sleep(300)
"""


def _started(tmp_path: Path):
    record = spawn([sys.executable, "-c", SUPERVISOR], tmp_path / "supervisor.log")
    deadline = time.monotonic() + 20
    while not (tmp_path / "supervisor.log").read_text().strip():
        assert time.monotonic() < deadline, "the supervisor did not start its child"
        time.sleep(0.05)
    return record, int((tmp_path / "supervisor.log").read_text().split()[0])


def test_group_members_list_the_running_processes_besides_the_leader(tmp_path: Path) -> None:
    record, child = _started(tmp_path)
    try:
        assert group_members(record.pid) == [child]
    finally:
        stop(record, timeout_s=1.0)
    assert not is_alive(record) and group_members(record.pid) == []


def test_a_supervisor_is_killed_once_its_group_has_ended(tmp_path: Path) -> None:
    record, child = _started(tmp_path)
    t0 = time.monotonic()
    assert stop(record, timeout_s=20.0, supervisor=True)
    assert time.monotonic() - t0 < 10.0, "waited for the timeout although the child had ended"
    assert not is_alive(record) and group_members(record.pid) == []
