"""Infeasible training requests are rejected at once, with what the cluster has and what to change."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sray.platform.train import resources
from sray.platform.train.resources import InfeasibleRequest, NodeResources, check_feasible

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ray_fixtures import ray_session  # noqa: E402,F401  (pytest fixture, used by name)


def _naive_capacity(nodes: list[NodeResources], cpus: float, gpus: float, limit: int = 200) -> int:
    """Place identical workers one at a time on any node with room left (reference for the formula)."""
    free = [[n.cpus, n.gpus] for n in nodes]
    placed = 0
    while placed < limit:
        for room in free:
            if room[0] >= cpus and room[1] >= gpus:
                room[0] -= cpus
                room[1] -= gpus
                placed += 1
                break
        else:
            return placed
    return placed


quarters = st.integers(0, 32).map(lambda q: q / 4)  # exact binary fractions: no rounding in the reference


@settings(max_examples=150, deadline=None)
@given(nodes=st.lists(st.tuples(quarters, st.integers(0, 4).map(float)), min_size=1, max_size=4),
       cpus=quarters, gpus=st.sampled_from([0.0, 0.25, 0.5, 1.0, 2.0]), workers=st.integers(1, 12))
def test_feasibility_matches_one_by_one_placement(nodes, cpus, gpus, workers):
    if cpus == 0 and gpus == 0:
        cpus = 1.0
    node_list = [NodeResources(f"n{i}", c, g) for i, (c, g) in enumerate(nodes)]
    fits = _naive_capacity(node_list, cpus, gpus) >= workers
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(resources, "live_nodes", lambda: node_list)
        if fits:
            check_feasible(workers, cpus, gpus)
        else:
            with pytest.raises(InfeasibleRequest):
                check_feasible(workers, cpus, gpus)


def _one_node(monkeypatch, cpus: float, gpus: float = 0.0) -> None:
    monkeypatch.setattr(resources, "live_nodes", lambda: [NodeResources("n0", cpus, gpus)])


def test_too_many_workers_names_what_exists_and_the_fix(monkeypatch):
    _one_node(monkeypatch, 2.0)
    with pytest.raises(InfeasibleRequest) as err:
        check_feasible(3, 1.0, 0.0)
    message = str(err.value)
    assert "3 worker(s)" in message and "2 CPUs" in message and "0 GPUs" in message
    assert "--workers to 2" in message


def test_gpu_request_on_cpu_cluster_suggests_cpu_training(monkeypatch):
    _one_node(monkeypatch, 8.0)
    with pytest.raises(InfeasibleRequest, match=r"no GPUs: use --gpus-per-worker 0"):
        check_feasible(1, 1.0, 1.0)


def test_oversized_worker_names_the_largest_node(monkeypatch):
    _one_node(monkeypatch, 8.0, 2.0)
    with pytest.raises(InfeasibleRequest, match=r"asks for 3 GPUs but the largest node has 2"):
        check_feasible(1, 1.0, 3.0)


def test_fractional_requests_fit_exactly(monkeypatch):
    _one_node(monkeypatch, 0.3)
    check_feasible(3, 0.1, 0.0)  # 0.3 / 0.1 is 2.9999999999999996 in floats
    _one_node(monkeypatch, 4.0, 2.0)
    check_feasible(4, 1.0, 0.5)


def test_live_local_ray_rejects_in_seconds(ray_session):
    check_feasible(2, 1.0, 0.0)  # the whole 2-CPU local instance
    start = time.perf_counter()
    with pytest.raises(InfeasibleRequest, match=r"2 CPUs and 0 GPUs \(1 node\(s\)\)"):
        check_feasible(3, 1.0, 0.0)
    with pytest.raises(InfeasibleRequest, match="no GPUs"):
        check_feasible(1, 1.0, 1.0)
    assert time.perf_counter() - start < 5.0
