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

import logging

QUIET = {"ray.train.v2._internal.execution.controller.placement_group_cleaner":
         ("Failed to query Ray Train Controller actor state",)}
"""Logger name -> message prefixes dropped from it."""

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
