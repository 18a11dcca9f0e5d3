"""One local cluster (``sray cluster up``) per test session, driven only through subprocesses.

The pytest process keeps its own in-process Ray (``ray_fixtures``); everything that talks to the
cluster runs as a child process with the cluster's token in its environment, as a user's shell
would. PostgreSQL is installed once (Debian's package, root only) or the cluster tests skip with
the reason. At teardown ``sray cluster down`` runs and the test checks that no process started
from the cluster folder is left.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

SRAY = [sys.executable, "-m", "sray.jobs.cli"]
"""The ``sray`` console script, run with this interpreter."""


@dataclass
class LocalCluster:
    """A running test cluster: its folder, its record and the environment its clients need."""

    dir: Path
    state: object
    """The :class:`sray.platform.cluster.state.ClusterState` that ``up`` wrote."""
    env: dict[str, str]
    """This process's environment plus the Ray token variables (and no RAY_ADDRESS)."""
    up_s: float
    """Wall-clock seconds ``sray cluster up`` took."""

    def sray(self, *args: str, timeout: float = 300, env: dict[str, str] | None = None,
             cwd: Path | None = None) -> subprocess.CompletedProcess:
        """Run ``sray ARGS`` as a client of the cluster; output captured as text."""
        return subprocess.run([*SRAY, *args], capture_output=True, text=True, timeout=timeout,
                              env=env or self.env, cwd=cwd or self.dir)

    def python(self, code: str, timeout: float = 120, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
        """Run ``python -c CODE`` as a client of the cluster; output captured as text."""
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout,
                              env=env or self.env, cwd=self.dir)

    def refresh(self) -> None:
        """Re-read the cluster record (after a node was restarted)."""
        from sray.platform.cluster.state import load_state

        self.state = load_state(self.dir)


def processes_under(folder: Path) -> list[str]:
    """Live (non-zombie) processes whose command line or working folder mentions ``folder``."""
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) == os.getpid():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            state = (proc / "stat").read_text().rsplit(")", 1)[1].split()[0]
            cwd = os.readlink(proc / "cwd")
        except OSError:
            continue
        if state != "Z" and (str(folder) in cmd or cwd.startswith(str(folder))):
            found.append(f"{proc.name}: {cmd[:160]}")
    return found


@dataclass
class ClusterInputs:
    """Tiny inputs on the cluster's shared storage, as a user would place them."""

    shards: Path
    """2 train scenes + 1 test scene, 20 views of 32x40 each (``train_fixtures.tiny_shards``' data)."""
    checkpoint: Path
    """A step-0 checkpoint of the tiny network, the fleet's shared model."""


@pytest.fixture(scope="session")
def local_cluster() -> Iterator[LocalCluster]:
    """``sray cluster up --workers 2`` in a short temp folder; ``down`` and a leftover check at the end."""
    from sray.platform.cluster.postgres import ensure_installed
    from sray.platform.cluster.processes import ClusterError
    from sray.platform.cluster.ray_nodes import auth_env
    from sray.platform.cluster.state import load_state

    root = Path(tempfile.mkdtemp(prefix="srayc", dir="/tmp"))  # short: Ray's socket paths stop at 107 bytes
    root.chmod(0o755)  # PostgreSQL runs as its own user under root
    try:
        ensure_installed(root / "apt.log")
    except ClusterError as e:
        shutil.rmtree(root, ignore_errors=True)
        pytest.skip(f"no PostgreSQL for the cluster tests: {e}")
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_ADDRESS")}
    env |= auth_env(root / "c" / "ray" / "auth_token") | {"RAY_USAGE_STATS_ENABLED": "0"}
    t0 = time.monotonic()
    up = subprocess.run([*SRAY, "cluster", "up", "--dir", str(root / "c"), "--workers", "2"], capture_output=True,
                        text=True, timeout=300, env=env)
    up_s = time.monotonic() - t0
    assert up.returncode == 0, up.stdout + up.stderr
    cluster = LocalCluster(root / "c", load_state(root / "c"), env, up_s)
    try:
        yield cluster
    finally:
        subprocess.run([*SRAY, "cluster", "down", "--dir", str(root / "c")], capture_output=True, timeout=120, env=env)
        time.sleep(1.0)
        left = processes_under(root)
        shutil.rmtree(root, ignore_errors=True)
        assert not left, "processes left behind by the cluster tests:\n" + "\n".join(left)


@pytest.fixture(scope="session")
def cluster_inputs(local_cluster: LocalCluster) -> ClusterInputs:
    """Tiny shards and a tiny S-Ray checkpoint under ``<shared storage>/inputs`` (made once per session)."""
    from fleet_fixtures import write_tiny_checkpoint

    from sray.data_tools.shards.writer import write_shards
    from sray.data_tools.synth.dataset import generate_dataset

    root = local_cluster.state.storage / "inputs"
    generate_dataset(root / "scenes", n_train=2, n_test=1, n_views=20, height=32, width=40, seed=3, progress=False)
    write_shards(root / "scenes", root / "shards", neighbours=8)
    return ClusterInputs(root / "shards", write_tiny_checkpoint(root / "shards", root / "base"))
