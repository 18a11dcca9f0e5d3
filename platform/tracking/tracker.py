"""The tracker interface: a driver prepares a run and hands its picklable :class:`RunHandle` to Ray workers, which open
loggers on it (so a restarted worker group writes into the same run). Tracking problems never stop a job: they warn."""

from __future__ import annotations

import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

log = logging.getLogger(__name__)

DRAIN_TIMEOUT_S = 120.0
"""How long a logger keeps retrying what it still holds when its job ends (:meth:`RunLogger.drain`)."""


@dataclass(frozen=True)
class RunHandle:
    """An opaque, picklable reference to one run of one tracker's store."""

    tracker: str
    """Registry name of the tracker that made the run (``mlflow``)."""
    store: str
    """Where the tracker keeps its runs (MLflow: the tracking URI)."""
    run_id: str
    experiment_id: str = ""
    ui_url: str = ""
    """Browser address of the run's page ('' when the tracker has no UI)."""
    ui_hint: str = ""
    """How to start that UI when it is not running by itself."""


class RunLogger(ABC):
    """Logs into one run; never raises because of the tracking store (it warns and buffers)."""

    handle: RunHandle

    @abstractmethod
    def log_params(self, config: Any) -> None:
        """Record a (nested) config dataclass or dict as the run's params."""

    @abstractmethod
    def log_metrics(self, metrics: Mapping[str, Any], step: int) -> None:
        """Record scalar metrics (floats, ints or 0-d tensors) at ``step`` (may be batched)."""

    @abstractmethod
    def log_artifact(self, path: Path, artifact_path: str | None = None) -> None:
        """Store a file, or a folder's contents, under ``artifact_path``; the file must stay until close()."""

    @abstractmethod
    def register_model(self, checkpoint: Path, name: str, alias: str = "latest") -> str | None:
        """Store a checkpoint as a new version of model ``name`` (``name@alias``); the version, or None for now."""

    @abstractmethod
    def close(self, status: str = "FINISHED") -> None:
        """Deliver what is buffered and put the run in ``status`` (FINISHED, FAILED or KILLED)."""

    def watch_system(self, node: str, interval_s: float) -> Callable[[], None]:
        """Record this machine's system metrics every ``interval_s`` s until the returned function is called."""
        return lambda: None

    def log_image(self, png: Path, artifact_path: str = "renders") -> None:
        """Store a PNG (a semantic render, a chart) under ``artifact_path``."""
        self.log_artifact(png, artifact_path)

    def flush(self, force: bool = False) -> bool:
        """Deliver what is buffered now; True when nothing is left (a logger without a buffer: always)."""
        return True

    def unsent_metrics(self) -> list[tuple[str, float, int]]:
        """Metrics logged but not delivered yet, ``(key, value, step)`` (a training checkpoint keeps them)."""
        return []

    def drain(self, timeout_s: float = DRAIN_TIMEOUT_S, poll_s: float = 2.0) -> bool:
        """Flush until nothing is left (True) or ``timeout_s`` passed (False)."""
        deadline = time.monotonic() + timeout_s
        while not self.flush(force=True):
            if time.monotonic() >= deadline:
                return False
            time.sleep(min(poll_s, max(deadline - time.monotonic(), 0.0)))
        return True

    def __enter__(self) -> RunLogger:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: Any) -> None:
        killed = exc_type is not None and issubclass(exc_type, KeyboardInterrupt)
        self.close("FINISHED" if exc_type is None else "KILLED" if killed else "FAILED")


class Tracker(ABC):
    """One tracking backend on one store: prepares runs, finds them again, opens loggers on them."""

    name: ClassVar[str]
    """Registry name (``--tracker``, ``run.tracker``)."""
    label: ClassVar[str]
    """Name shown to people in messages (``MLflow``)."""

    def __init__(self, store: str) -> None:
        self.store = store

    @classmethod
    @abstractmethod
    def default_store(cls, workdir: Path) -> str:
        """The store used when none is given: one inside ``workdir``."""

    def ensure_store(self) -> None:
        """Make the store usable now, before workers fan out; ConnectionError naming the store otherwise."""

    @abstractmethod
    def start_run(self, experiment: str, run_name: str, tags: Mapping[str, str] | None = None,
                  parent: RunHandle | None = None) -> RunHandle:
        """Create a new RUNNING run in ``experiment`` (created if needed), nested under ``parent``."""

    @abstractmethod
    def find_run(self, experiment: str, run_name: str) -> RunHandle | None:
        """The newest run called ``run_name`` in ``experiment``, or None (no side effects)."""

    @abstractmethod
    def get_run(self, run_id: str) -> RunHandle:
        """The handle of an existing run; raises (any error) when the store has no such run."""

    @abstractmethod
    def set_status(self, handle: RunHandle, status: str) -> None:
        """Put a run in ``status`` (RUNNING, FINISHED, FAILED or KILLED); raises on failure."""

    @abstractmethod
    def set_tags(self, handle: RunHandle, tags: Mapping[str, str]) -> None:
        """Set tags on a run; raises on failure."""

    @abstractmethod
    def logger(self, handle: RunHandle, **options: Any) -> RunLogger:
        """A logger writing into ``handle``'s run (``options``: the implementation's batching settings)."""

    def resume_run(self, experiment: str, run_name: str) -> RunHandle:
        """The run of a job being resumed, marked RUNNING again; LookupError when there is none."""
        handle = self.find_run(experiment, run_name)
        if handle is None:
            raise LookupError(f"no {self.label} run named {run_name!r} in experiment {experiment!r} at {self.store}; "
                              "check --name/--resume and --tracking-uri (they must match the original job)")
        self.set_status(handle, "RUNNING")
        return handle

    def end_run(self, handle: RunHandle, status: str) -> bool:
        """Mark a run FINISHED, FAILED or KILLED from the driver; warns and returns False on failure."""
        try:
            self.set_status(handle, status)
            return True
        except Exception as e:  # noqa: BLE001 - tracking problems never crash the job
            log.warning("could not mark %s run %s as %s at %s: %s", self.label, handle.run_id, status, self.store, e)
            return False

    def tag_run(self, handle: RunHandle, tags: Mapping[str, str]) -> bool:
        """Set tags from the driver; warns and returns False on failure."""
        try:
            self.set_tags(handle, tags)
            return True
        except Exception as e:  # noqa: BLE001 - tracking problems never crash the job
            log.warning("could not tag %s run %s: %s", self.label, handle.run_id, e)
            return False
