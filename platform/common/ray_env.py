"""The Ray environment of an sray job: the controller's poll interval, the workers' environment, the filters
that silence Ray's known log floods, and the hook every Ray worker process of a job runs first.

**Polling.** Ray Train's controller learns that a worker group has started, reported a checkpoint or finished
only when it polls the group, every ``RAY_TRAIN_HEALTH_CHECK_INTERVAL_S`` seconds (Ray's default 2 s; a missed
poll only counts against a worker after 10 minutes). A short job waits for those polls at its start, at each
report and at its end: a 6-step local job took 33.4 s with 2 s and 27.7 s with 0.5 s (two alternating pairs,
2-core machine). On one machine a poll is a local call, so sray's local Ray and local cluster poll every 0.5 s
(:data:`TRAIN_POLL_ENV`) unless the user set the variable; clusters of many machines keep Ray's default.

**Log floods.** Ray Train V2's placement-group cleaner (a detached actor) polls the controller's state through
Ray's state API, which only the dashboard serves. Without a dashboard (sray's local, in-process Ray) every poll
fails and logs "Failed to query Ray Train Controller actor state" every few seconds: 14 lines in one demo, 138
in one 80-step run, all forwarded to the user's terminal. The cleaner still works (the controller ends its own
placement group); the line tells a user nothing. The worker-process hook installs the filters of :data:`QUIET`
in the very process that logs the line; anything else those loggers say still shows.

**The hook.** The drivers pass :data:`SETUP_HOOK` in the job's runtime environment, so :func:`setup_worker`
runs in each process Ray starts for the job (Ray Train's controller, its placement-group cleaner, the training
workers, the fleet's scene tasks) before that process does anything else.
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
"""Logger name -> message prefixes dropped from it. Besides the cleaner's flood: at every checkpoint each
worker announced its report ("Reporting training result 3: TrainingReport(checkpoint=..., metrics=...)
from rank 1") and rank 0 the copy in Ray's own storage folder, 3 lines of Ray's internals per checkpoint
beside sray's own progress line; and when the cores are busy the controller's resource request to Ray's
autoscaling coordinator can time out, which Ray logs as a warning with a full traceback that its own message
calls safe to ignore (the request is sent again at the next poll; a job of fixed size does not depend on it)."""

TRAIN_WORKER_ENV = {"RAY_TRAIN_ENABLE_PRINT_PATCH": "0"}
"""Environment of Ray Train workers. Ray Train V2 replaces ``print`` in its workers with a function that
sends each line to the root logger and, when ``sys.stdout`` is wrapped (it is, by Ray's own log
capture), also prints it: every line a worker printed reached the driver twice. Without the patch a
print is forwarded once, by Ray's normal worker-log streaming."""

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
    """Set ``RAY_ADDRESS`` to this worker's own cluster (unless it is set). Ray code that looks its cluster up
    with ``address="auto"`` (Ray Train's placement-group cleaner) otherwise lists every Ray on the host and,
    with a second one running (a cluster, another local job, a test session), dies with "Found multiple
    active Ray instances" and a traceback in the user's output."""
    os.environ.setdefault("RAY_ADDRESS", ray.get_runtime_context().gcs_address)


def setup_worker() -> None:
    """The hook: quiet Ray's known log floods (:func:`quiet_ray_logs`), pin the cluster address."""
    quiet_ray_logs()
    pin_cluster_address()
