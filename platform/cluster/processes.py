"""Background processes of a local cluster: free ports, start detached, check and stop by recorded id. A process is
recorded with its start time (``/proc/<pid>/stat``), so a later process that got the same pid is never signalled;
each leads its own process group, and stopping it signals the whole group (the helpers it spawned too)."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path


class ClusterError(RuntimeError):
    """A local cluster cannot be started or used; the message says what to do."""


@dataclass(frozen=True)
class ProcessRecord:
    """A started process: pid (also its group id: it leads its session) and start time in clock ticks since boot."""

    pid: int
    started: int


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nobody listens on now (the kernel's choice)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def port_open(host: str, port: int) -> bool:
    """True when something accepts TCP connections at ``host:port``."""
    try:
        with socket.create_connection((host, port), timeout=1.0):
            return True
    except OSError:
        return False


def _stat(pid: int) -> list[str]:
    """Fields of ``/proc/<pid>/stat`` after the command name (state, ppid, pgrp, ...); [] when it is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return []
    return stat[stat.rindex(")") + 2:].split()


def start_time(pid: int) -> int | None:
    """The process's start time (clock ticks since boot), or None when there is no such live process."""
    fields = _stat(pid)
    return None if not fields or fields[0] == "Z" else int(fields[19])


def is_alive(record: ProcessRecord) -> bool:
    """True while the recorded process runs (and is the one recorded, not a reused pid)."""
    return start_time(record.pid) == record.started


def spawn(cmd: list[str], log_path: Path, env: Mapping[str, str] | None = None, user: str | None = None,
          cwd: Path | None = None) -> ProcessRecord:
    """Start ``cmd`` detached (own session, stdin closed, output to ``log_path``) and record it; ``user``: run it
    as that user (needs root), e.g. ``postgres``, which refuses to run as root."""
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, "ab") as log:
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                env=dict(env) if env is not None else None, start_new_session=True,
                                user=user, group=user, extra_groups=[] if user else None, cwd=cwd)
    started = start_time(proc.pid)
    if started is None:
        raise ClusterError(f"{cmd[0]} exited at once; see {log_path}")
    return ProcessRecord(proc.pid, started)


def wait_until(check: Callable[[], bool], timeout_s: float, what: str, log_path: Path | None = None,
               alive: ProcessRecord | None = None) -> None:
    """Poll ``check`` until True; ClusterError naming ``what``, ``log_path`` at ``timeout_s`` or if ``alive`` died."""
    t0 = time.monotonic()
    where = f"; see {log_path}" if log_path else ""
    while not check():
        if alive is not None and not is_alive(alive):
            raise ClusterError(f"{what} exited before it was ready{where}")
        if time.monotonic() - t0 > timeout_s:
            raise ClusterError(f"{what} was not ready within {timeout_s:.0f} s{where}")
        time.sleep(0.25)


def stop(record: ProcessRecord, timeout_s: float = 20.0, sig: int = signal.SIGTERM, supervisor: bool = False) -> bool:
    """Send ``sig`` to the recorded process's group, SIGKILL after ``timeout_s``; True when it ran. A ``supervisor``
    leader (``ray start --block``, whose exit can sit out the wait) gets SIGKILL once the rest of its group ended."""
    if not is_alive(record):
        return False
    for signum in (sig, signal.SIGKILL):
        try:
            os.killpg(record.pid, signum)
        except ProcessLookupError:
            return True
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and is_alive(record):
            if supervisor and signum != signal.SIGKILL and not group_members(record.pid):
                break
            time.sleep(0.1)
        if not is_alive(record):
            break
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(record.pid, signal.SIGKILL)  # helpers of the group that outlived its leader
    return True


def group_members(pgid: int) -> list[int]:
    """Running (non-zombie) processes of group ``pgid`` other than its leader, from ``/proc``."""
    pids = [int(p.name) for p in Path("/proc").iterdir() if p.name.isdigit() and int(p.name) != pgid]
    return [pid for pid in pids if (fields := _stat(pid)) and fields[0] != "Z" and int(fields[2]) == pgid]
