"""The Ray environment of an sray job: poll interval, workers' environment, log filters, the worker setup hook."""

from __future__ import annotations

import importlib.util
import logging
import os

import ray

TRAIN_POLL_ENV = {"RAY_TRAIN_HEALTH_CHECK_INTERVAL_S": "0.5"}
"""Environment of a driver on one machine: Ray Train's controller sees workers start, report and end only by polling."""


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
"""Logger name -> message prefixes dropped: the placement-group cleaner's failing poll every few seconds (without a
dashboard), Ray's 3 lines per checkpoint, and a timed-out autoscaler request's traceback Ray calls safe to ignore."""

TRAIN_WORKER_ENV = {"RAY_TRAIN_ENABLE_PRINT_PATCH": "0"}
"""Environment of Ray Train workers: without Ray's ``print`` patch a printed line reaches the driver once, not twice."""

SETUP_HOOK = "sray.platform.common.ray_env.setup_worker"
"""Import path of :func:`setup_worker`, for ``runtime_env={"worker_process_setup_hook": ...}``."""


class DropPrefixes(logging.Filter):
    """Drops log records whose message starts with one of ``prefixes``."""

    def __init__(self, prefixes: tuple[str, ...]) -> None:
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


def setup_worker() -> None:
    """The hook: quiet Ray's log floods and pin ``RAY_ADDRESS`` to this cluster (Ray code that looks up ``"auto"``
    dies with "Found multiple active Ray instances" when a second Ray runs on the host)."""
    quiet_ray_logs()
    os.environ.setdefault("RAY_ADDRESS", ray.get_runtime_context().gcs_address)
