"""The Ray environment of an sray job: the controller's poll interval, the workers' environment, the filters
that silence Ray's known log floods, and the hook every Ray worker process of a job runs first.

Ray Train's controller sees a worker group start, report and finish only when it polls it (Ray's default every 2 s):
on one machine a poll is a local call, so sray's local Ray polls every 0.5 s (:data:`TRAIN_POLL_ENV`), which made
a short job start and end seconds sooner. The drivers pass :data:`SETUP_HOOK` in the job's runtime environment, so
:func:`setup_worker` runs first in each process Ray starts for the job (controller, placement-group cleaner,
training workers, fleet tasks).
"""

from __future__ import annotations

import importlib.util
import logging
import os

import ray

TRAIN_POLL_ENV = {"RAY_TRAIN_HEALTH_CHECK_INTERVAL_S": "0.5"}
"""Environment of a driver on one machine; Ray Train passes the variable on to its controller."""


def _ray_file_logger(relative: str) -> str:
    """Name of a logger Ray creates with ``logging.getLogger(__file__)``: the module's path in this install."""
    spec = importlib.util.find_spec("ray")
    return os.path.join(spec.submodule_search_locations[0], relative) if spec and spec.submodule_search_locations \
        else relative


QUIET = {"ray.train.v2._internal.execution.controller.placement_group_cleaner":
         ("Failed to query Ray Train Controller actor state",),
         "ray.train.v2._internal.execution.storage": ("Checkpoint successfully created at",),
         _ray_file_logger("train/v2/_internal/execution/context.py"): ("Reporting training result",),
         "ray.train.v2._internal.execution.scaling_policy.autoscaling_coordinator_client":
         ("Failed to send resource request for",)}
"""Logger name -> message prefixes dropped from it: the placement-group cleaner's failing poll of the state API
(only a dashboard serves it; the local Ray has none) every few seconds, Ray's 3 lines per checkpoint beside sray's
own progress line, and the autoscaler request that times out on busy cores, with a traceback Ray calls safe to
ignore (a job of fixed size does not depend on it)."""

TRAIN_WORKER_ENV = {"RAY_TRAIN_ENABLE_PRINT_PATCH": "0"}
"""Environment of Ray Train workers: without Ray Train's ``print`` patch each printed line reaches the driver once,
not twice (through the root logger and Ray's log capture)."""

SETUP_HOOK = "sray.platform.common.ray_env.setup_worker"
"""Import path of :func:`setup_worker`, for ``runtime_env={"worker_process_setup_hook": ...}``."""


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


def pin_cluster_address() -> None:
    """Set ``RAY_ADDRESS`` to this worker's own cluster (unless set): Ray code that looks up ``address="auto"``
    (the placement-group cleaner) dies with "Found multiple active Ray instances" when a second Ray runs."""
    os.environ.setdefault("RAY_ADDRESS", ray.get_runtime_context().gcs_address)


def setup_worker() -> None:
    """The hook: quiet Ray's known log floods (:func:`quiet_ray_logs`), pin the cluster address."""
    quiet_ray_logs()
    pin_cluster_address()
