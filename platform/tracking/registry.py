"""The tracker registry: every :class:`~sray.platform.tracking.tracker.Tracker` by name.

Jobs choose one by name (``run.tracker`` of a training config, ``tracker`` of a fleet config,
``sray eval --tracker``; default ``mlflow``) and open loggers on the handles it made. A handle
names its tracker, so a Ray worker finds the same implementation by :func:`open_logger` as long as
the tracker is registered in the worker's process too: trackers registered here, at import, always
are; one registered at run time (a test, a notebook) serves jobs that run in that process.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sray.platform.tracking.mlflow_tracker import MlflowTracker
from sray.platform.tracking.tracker import RunHandle, RunLogger, Tracker

DEFAULT_TRACKER = MlflowTracker.name
"""The tracker a job uses unless told otherwise."""

TRACKERS: dict[str, type[Tracker]] = {MlflowTracker.name: MlflowTracker}
"""Every known tracker class by name."""


def register_tracker(tracker: type[Tracker]) -> type[Tracker]:
    """Add (or replace) ``tracker`` under its ``name``; returns it (usable as a class decorator)."""
    TRACKERS[tracker.name] = tracker
    return tracker


def tracker_class(name: str) -> type[Tracker]:
    """The registered tracker class ``name``; ValueError names the known trackers otherwise."""
    try:
        return TRACKERS[name]
    except KeyError:
        raise ValueError(f"unknown tracker {name!r}; known: {sorted(TRACKERS)}") from None


def get_tracker(name: str = DEFAULT_TRACKER, store: str = "") -> Tracker:
    """Tracker ``name`` on ``store`` ('' = its default store in the working directory)."""
    cls = tracker_class(name)
    return cls(store or cls.default_store(Path.cwd()))


def open_logger(handle: RunHandle, **options: Any) -> RunLogger:
    """A logger writing into the run ``handle`` refers to, through the tracker that made it."""
    return get_tracker(handle.tracker, handle.store).logger(handle, **options)
