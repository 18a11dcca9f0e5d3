"""Every :class:`~sray.platform.tracking.tracker.Tracker` by name; a Ray worker opens the one its handle names."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sray.platform.tracking.mlflow_tracker import MlflowTracker
from sray.platform.tracking.tracker import RunHandle, RunLogger, Tracker

DEFAULT_TRACKER = MlflowTracker.name
TRACKERS: dict[str, type[Tracker]] = {MlflowTracker.name: MlflowTracker}


def register_tracker(tracker: type[Tracker]) -> type[Tracker]:
    """Add (or replace) ``tracker`` under its ``name``; returns it (usable as a class decorator)."""
    TRACKERS[tracker.name] = tracker
    return tracker


def get_tracker(name: str = DEFAULT_TRACKER, store: str = "") -> Tracker:
    """Tracker ``name`` on ``store`` ('' = its default store in the working directory); ValueError if unknown."""
    if name not in TRACKERS:
        raise ValueError(f"unknown tracker {name!r}; known: {sorted(TRACKERS)}")
    cls = TRACKERS[name]
    return cls(store or cls.default_store(Path.cwd()))


def open_logger(handle: RunHandle, **options: Any) -> RunLogger:
    """A logger writing into the run ``handle`` refers to, through the tracker that made it."""
    return get_tracker(handle.tracker, handle.store).logger(handle, **options)
