"""One local Ray instance for the whole test session (starting Ray costs 2.5-7 s here).

Use from a test module (the tests folder is not a package)::

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from ray_fixtures import ray_session  # noqa: F401  (pytest finds the fixture by name)

or import it once in conftest.py. Whichever definition pytest runs first starts Ray; any other
finds it running and reuses it, so Ray starts at most once per session.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator

import pytest

RAY_CPUS = 2
"""Logical CPUs of the test Ray instance (the CI machine has 2 cores)."""
OBJECT_STORE_BYTES = 100 * 1024 * 1024
"""A modest object store: tests move small tensors only."""


@pytest.fixture(scope="session")
def ray_session() -> Iterator[dict[str, float]]:
    """A running local Ray (``address="local"``, no dashboard); yields ``ray.cluster_resources()``."""
    from sray.platform.train.launcher import LOCAL_WORKER_ENV

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    for key, value in LOCAL_WORKER_ENV.items():  # as sray's own local Ray (launcher.init_ray)
        os.environ.setdefault(key, value)
    import ray

    if ray.is_initialized():
        yield ray.cluster_resources()
        return
    # A short temp dir: Ray's AF_UNIX socket paths fail beyond 107 bytes.
    temp_dir = tempfile.mkdtemp(prefix="ray", dir="/tmp")
    ray.init(num_cpus=RAY_CPUS, address="local", include_dashboard=False, log_to_driver=False,
             object_store_memory=OBJECT_STORE_BYTES, _temp_dir=temp_dir)
    try:
        yield ray.cluster_resources()
    finally:
        ray.shutdown()
        shutil.rmtree(temp_dir, ignore_errors=True)
