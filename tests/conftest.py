"""Shared pytest set-up: CPU by default; tests marked ``gpu`` skip cleanly without CUDA."""

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
sys.path.insert(0, str(Path(__file__).resolve().parent))  # shared fixture modules beside the tests

from cluster_fixtures import cluster_inputs, local_cluster  # noqa: E402,F401  (one local cluster per session)
from ray_fixtures import ray_session  # noqa: E402,F401  (session-wide local Ray, started on first use)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Skip ``@pytest.mark.gpu`` tests when no CUDA device is visible."""
    import torch

    if torch.cuda.is_available():
        return
    skip = pytest.mark.skip(reason="needs a CUDA device (none visible on this machine)")
    for item in items:
        if "gpu" in item.keywords:
            item.add_marker(skip)
