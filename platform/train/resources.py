"""Reject a training request the Ray cluster cannot place, in seconds instead of waiting forever.

An infeasible ``ScalingConfig`` (say 3 one-CPU workers on a 2-CPU machine) makes
``TorchTrainer.fit()`` wait indefinitely. :func:`check_feasible` compares the request with the
cluster first. Each worker must fit on one node, so the count is done per node: a node with ``c``
CPUs and ``g`` GPUs hosts ``min(c // cpus_per_worker, g // gpus_per_worker)`` identical workers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import ray

_EPS = 1e-9
"""Slack for fractional requests (0.1 * 3 is not exactly 0.3)."""


class InfeasibleRequest(RuntimeError):
    """The cluster cannot host the requested workers; the message says what it has and what to change."""


@dataclass(frozen=True)
class NodeResources:
    """CPUs and GPUs of one alive Ray node."""

    name: str
    """Node address or id, for messages."""
    cpus: float
    """Logical CPUs Ray may schedule on the node."""
    gpus: float
    """GPUs Ray may schedule on the node."""


def _fits(have: float, need: float) -> int:
    """How many requests of ``need`` fit into ``have`` (unbounded when nothing is needed)."""
    if need <= 0:
        return 1 << 30
    return int(math.floor(have / need + _EPS))


def workers_per_node(node: NodeResources, cpus_per_worker: float, gpus_per_worker: float) -> int:
    """Identical workers of this size the node can host at once."""
    return min(_fits(node.cpus, cpus_per_worker), _fits(node.gpus, gpus_per_worker))


def nodes_from_totals(resources: dict[str, float]) -> list[NodeResources]:
    """One pseudo-node from a ``ray.cluster_resources()``-style totals dict (keys ``CPU``, ``GPU``).

    With totals only, placement across nodes is unknown: the check is then exact for one node and
    optimistic for several.
    """
    return [NodeResources("cluster", float(resources.get("CPU", 0.0)), float(resources.get("GPU", 0.0)))]


def live_nodes() -> list[NodeResources]:
    """Alive nodes of the Ray cluster this process is connected to (``ray.init`` already called)."""
    return [NodeResources(str(n.get("NodeManagerAddress") or n.get("NodeID")),
                          float(n["Resources"].get("CPU", 0.0)), float(n["Resources"].get("GPU", 0.0)))
            for n in ray.nodes() if n.get("Alive")]


def _fmt(x: float) -> str:
    return f"{x:g}"


def check_feasible(num_workers: int, cpus_per_worker: float, gpus_per_worker: float,
                   resources: dict[str, float] | None = None) -> None:
    """Raise :class:`InfeasibleRequest` unless ``num_workers`` workers of this size can run at once.

    ``resources``: cluster totals like ``ray.cluster_resources()``; None asks the connected Ray
    cluster node by node. ValueError for a malformed request (no workers, negative sizes).
    """
    if num_workers < 1:
        raise ValueError(f"--workers must be at least 1, got {num_workers}")
    if cpus_per_worker < 0 or gpus_per_worker < 0:
        raise ValueError(f"per-worker CPUs and GPUs must be >= 0, got {cpus_per_worker} and {gpus_per_worker}")
    if cpus_per_worker == 0 and gpus_per_worker == 0:
        raise ValueError("each worker needs some CPU or GPU; got 0 CPUs and 0 GPUs per worker")
    nodes = nodes_from_totals(resources) if resources is not None else live_nodes()
    capacity = sum(workers_per_node(n, cpus_per_worker, gpus_per_worker) for n in nodes)
    if capacity >= num_workers:
        return
    total_cpus = sum(n.cpus for n in nodes)
    total_gpus = sum(n.gpus for n in nodes)
    where = "cluster totals" if resources is not None else f"{len(nodes)} node(s)"
    lines = [
        f"The Ray cluster cannot run {num_workers} worker(s) of {_fmt(cpus_per_worker)} CPU + "
        f"{_fmt(gpus_per_worker)} GPU each: it has {_fmt(total_cpus)} CPUs and {_fmt(total_gpus)} GPUs "
        f"({where}) and fits {capacity} such worker(s) at once.",
    ]
    if resources is None and len(nodes) > 1:
        lines.append("per node: " + ", ".join(f"{n.name} {_fmt(n.cpus)} CPU/{_fmt(n.gpus)} GPU" for n in nodes))
    if gpus_per_worker > 0 and total_gpus == 0:
        lines.append("There are no GPUs: use --gpus-per-worker 0 to train on CPUs, or --address to join a "
                     "cluster with GPUs.")
    elif capacity > 0:
        lines.append(f"Lower --workers to {capacity}, or add nodes.")
    else:
        max_cpus = max((n.cpus for n in nodes), default=0.0)
        max_gpus = max((n.gpus for n in nodes), default=0.0)
        if cpus_per_worker > max_cpus + _EPS:
            lines.append(f"Each worker asks for {_fmt(cpus_per_worker)} CPUs but the largest node has "
                         f"{_fmt(max_cpus)}: lower the CPUs per worker.")
        if gpus_per_worker > max_gpus + _EPS:
            lines.append(f"Each worker asks for {_fmt(gpus_per_worker)} GPUs but the largest node has "
                         f"{_fmt(max_gpus)}: lower --gpus-per-worker to at most {_fmt(max_gpus)}.")
    raise InfeasibleRequest(" ".join(lines))
