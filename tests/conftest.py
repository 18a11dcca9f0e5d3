"""Shared pytest set-up: CPU by default; tests marked ``gpu`` skip cleanly without CUDA; under pytest-xdist
(``make test``) one torch thread per worker and one worker per test module (one for all cluster tests)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
from hypothesis import settings

# Property tests: CI replays a fixed example sequence so a run is reproducible; set
# SRAY_HYPOTHESIS=explore to draw fresh random examples on every run when hunting bugs.
settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("SRAY_HYPOTHESIS", "ci"))

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
if os.environ.get("PYTEST_XDIST_WORKER"):  # two test processes share the two cores: one torch thread each
    import torch

    torch.set_num_threads(1)
sys.path.insert(0, str(Path(__file__).resolve().parent))  # shared fixture modules beside the tests

from cluster_fixtures import cluster_inputs, local_cluster  # noqa: E402,F401  (one local cluster per session)
from ray_fixtures import ray_session  # noqa: E402,F401  (session-wide local Ray, started on first use)

from sray.platform.common import machine  # noqa: E402  (its throughput probe is fixed below)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Keep each module on one xdist worker (every module with a cluster test on one), and skip
    ``@pytest.mark.gpu`` tests when no CUDA device is visible."""
    import torch

    on_cluster = {item.path for item in items if "local_cluster" in getattr(item, "fixturenames", ())}
    for item in items:
        group = "cluster" if item.path in on_cluster else item.path.stem
        item.add_marker(pytest.mark.xdist_group(group))
    if torch.cuda.is_available():
        return
    skip = pytest.mark.skip(reason="needs a CUDA device (none visible on this machine)")
    for item in items:
        if "gpu" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(autouse=True)
def _fixed_machine_probe(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every stored benchmark table carries a machine descriptor whose throughput probe runs a fresh process (seconds);
    outside tests/test_machine.py, which tests the probe itself, a fixed figure stands in for it."""
    if request.path.name == "test_machine.py":
        return
    monkeypatch.setattr(machine, "probe_in_fresh_process", lambda *args, **kwargs: 1.0)
