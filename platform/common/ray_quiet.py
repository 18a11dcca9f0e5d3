"""Silence Ray's known, harmless log floods in every process of a job (a Ray worker-process hook).

Ray Train V2's placement-group cleaner (a detached actor) polls the controller's state through
Ray's state API, which only the dashboard serves. Without a dashboard (sray's local, in-process
Ray) every poll fails and logs "Failed to query Ray Train Controller actor state" every few seconds:
14 lines in one demo, 138 in one 80-step run, all forwarded to the user's terminal. The cleaner still
works (the controller ends its own placement group); the line tells a user nothing. The job's
worker-process hook (:mod:`sray.platform.common.ray_worker_setup`) installs the filter in the very
process that logs the line; anything else those loggers say still shows.
"""

from __future__ import annotations

import importlib.util
import logging
import os


def _ray_file_logger(relative: str) -> str:
    """Name of a logger Ray creates with ``logging.getLogger(__file__)``: the module's path in this install."""
    spec = importlib.util.find_spec("ray")
    return os.path.join(spec.submodule_search_locations[0], relative) if spec and spec.submodule_search_locations \
        else relative


QUIET = {"ray.train.v2._internal.execution.controller.placement_group_cleaner":
         ("Failed to query Ray Train Controller actor state",),
         "ray.train.v2._internal.execution.storage": ("Checkpoint successfully created at",),
         _ray_file_logger("train/v2/_internal/execution/context.py"): ("Reporting training result",)}
"""Logger name -> message prefixes dropped from it. Besides the cleaner's flood: at every checkpoint each
worker announced its report ("Reporting training result 3: TrainingReport(checkpoint=..., metrics=...)
from rank 1") and rank 0 the copy in Ray's own storage folder, 3 lines of Ray's internals per checkpoint
beside sray's own progress line."""

TRAIN_WORKER_ENV = {"RAY_TRAIN_ENABLE_PRINT_PATCH": "0"}
"""Environment of Ray Train workers. Ray Train V2 replaces ``print`` in its workers with a function that
sends each line to the root logger and, when ``sys.stdout`` is wrapped (it is, by Ray's own log
capture), also prints it: every line a worker printed reached the driver twice. Without the patch a
print is forwarded once, by Ray's normal worker-log streaming."""


class DropPrefixes(logging.Filter):
    """Drops log records whose message starts with one of ``prefixes``."""

    def __init__(self, prefixes: tuple[str, ...]) -> None:
        """``prefixes``: message beginnings to drop."""
        super().__init__()
        self.prefixes = prefixes

    def filter(self, record: logging.LogRecord) -> bool:
        """False (drop) for a record starting with a listed prefix."""
        return not record.getMessage().startswith(self.prefixes)


def quiet_ray_logs() -> None:
    """Install the filters of :data:`QUIET` in this process (idempotent)."""
    for name, prefixes in QUIET.items():
        logger = logging.getLogger(name)
        if not any(isinstance(f, DropPrefixes) for f in logger.filters):
            logger.addFilter(DropPrefixes(prefixes))
