"""A local cluster's record ``<dir>/cluster.json`` (owner-only): ports, database password, process ids with start
times, so ``down`` stops exactly those; kept for the next ``up``, changed under a lock (:func:`update_state`)."""

from __future__ import annotations

import fcntl
import json
import os
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

from sray.data_tools.atomic import atomic_write_json
from sray.platform.cluster.processes import ClusterError, ProcessRecord, is_alive

STATE_FILE = "cluster.json"  # the record's file name inside the cluster folder
LOCK_FILE = "cluster.lock"  # file locked (``flock``) while one command reads, changes and writes the record
FORMAT = "sray-cluster/1"  # format tag of the record


@dataclass
class ClusterState:
    """All ``sray cluster`` knows of a cluster folder: the folder (absolute; database, artifacts, Ray temp dirs, shared
    storage, logs), the ``sray`` role's password, the ``postgres``, ``mlflow``, ``gcs`` and ``dashboard`` ports, the
    last ``up``'s workers and CPUs per node, each part's process (-> ``{pid, started}``) and start-up seconds."""

    dir: str
    password: str
    ports: dict[str, int] = field(default_factory=dict)
    workers: int = 2
    cpus_per_worker: int = 1
    processes: dict[str, dict[str, int]] = field(default_factory=dict)
    startup_s: dict[str, float] = field(default_factory=dict)

    @property
    def root(self) -> Path:
        """The cluster folder."""
        return Path(self.dir)

    @property
    def token_path(self) -> Path:
        """The Ray auth token every node and client shares."""
        return self.root / "ray" / "auth_token"

    @property
    def storage(self) -> Path:
        """The storage path shared by all nodes (jobs' checkpoints, Ray Train's run folders)."""
        return self.root / "shared"

    @property
    def ray_address(self) -> str:
        """The GCS address for ``--address`` (``ray.init`` and ``ray start``)."""
        return f"127.0.0.1:{self.ports['gcs']}"

    @property
    def dashboard_url(self) -> str:
        """The Ray dashboard and Jobs API (``sray submit --address``)."""
        return f"http://127.0.0.1:{self.ports['dashboard']}"

    @property
    def tracking_uri(self) -> str:
        """The MLflow server for ``--tracking-uri``."""
        return f"http://127.0.0.1:{self.ports['mlflow']}"

    def record(self, name: str) -> ProcessRecord | None:
        """The recorded process ``name``, or None."""
        entry = self.processes.get(name)
        return ProcessRecord(**entry) if entry else None

    def alive(self) -> dict[str, bool]:
        """Each recorded process -> whether it still runs."""
        return {name: is_alive(ProcessRecord(**entry)) for name, entry in self.processes.items()}

    def save(self) -> None:
        """Write the record (owner-only permissions: it holds the database password)."""
        path = self.root / STATE_FILE
        atomic_write_json(path, {"format": FORMAT, **asdict(self)})
        os.chmod(path, 0o600)


def load_state(root: Path) -> ClusterState | None:
    """The record in ``root``, or None when there is none; ClusterError for an unreadable one."""
    path = Path(root) / STATE_FILE
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
        if data.pop("format", None) != FORMAT:
            raise ValueError(f"field 'format' is not {FORMAT!r}")
        return ClusterState(**data)
    except (ValueError, TypeError) as e:
        raise ClusterError(f"{path}: not a sray cluster record ({e}); pass another --dir or remove the file") from None


def update_state(root: Path, change: Callable[[ClusterState], None]) -> ClusterState:
    """Apply ``change`` to the record on disk under the folder's lock; the new record (ClusterError: no record)."""
    with open(Path(root) / LOCK_FILE, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        state = load_state(root)
        if state is None:
            raise ClusterError(f"{Path(root).resolve()}: no cluster record ({STATE_FILE}) to update")
        change(state)
        state.save()
    return state
