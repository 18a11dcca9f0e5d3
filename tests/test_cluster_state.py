"""The local cluster's record (``<dir>/cluster.json``): concurrent commands keep each other's changes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from sray.platform.cluster.state import ClusterState, load_state

WRITER = """
import sys
from sray.platform.cluster.state import update_state
for i in range(40):
    update_state(sys.argv[1], lambda s: s.processes.update({f"{sys.argv[2]}-{i}": {"pid": i, "started": i}}))
"""


def test_concurrent_updates_keep_every_process_record(tmp_path: Path) -> None:
    """Two processes record 40 processes each at the same time (a node restart beside a tracking-server
    restart); the record ends up with all 80."""
    ClusterState(dir=str(tmp_path), password="pw").save()
    writers = [subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path), name]) for name in ("a", "b")]
    assert [w.wait(timeout=120) for w in writers] == [0, 0]
    assert set(load_state(tmp_path).processes) == {f"{name}-{i}" for name in ("a", "b") for i in range(40)}
