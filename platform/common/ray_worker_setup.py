"""What every Ray worker process of an sray job does first: the job's ``worker_process_setup_hook``.

The drivers pass :data:`SETUP_HOOK` in the job's runtime environment, so it runs in each process
Ray starts for the job (Ray Train's controller, its placement-group cleaner, the training workers,
the fleet's scene tasks) before that process does anything else.
"""

from __future__ import annotations

import os

from sray.platform.common.ray_quiet import quiet_ray_logs

SETUP_HOOK = "sray.platform.common.ray_worker_setup.setup_worker"
"""Import path of :func:`setup_worker`, for ``runtime_env={"worker_process_setup_hook": ...}``."""


def pin_cluster_address() -> None:
    """Set ``RAY_ADDRESS`` to this worker's own cluster (unless it is set). Ray code that looks its cluster up
    with ``address="auto"`` (Ray Train's placement-group cleaner) otherwise lists every Ray on the host and,
    with a second one running (a cluster, another local job, a test session), dies with "Found multiple
    active Ray instances" and a traceback in the user's output."""
    import ray

    os.environ.setdefault("RAY_ADDRESS", ray.get_runtime_context().gcs_address)


def setup_worker() -> None:
    """The hook: quiet Ray's known log floods (:mod:`sray.platform.common.ray_quiet`), pin the cluster address."""
    quiet_ray_logs()
    pin_cluster_address()
