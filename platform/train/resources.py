"""Reject a request the Ray cluster cannot place (``TorchTrainer.fit()`` would wait forever), counted per node."""

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
    """CPUs and GPUs Ray may schedule on one alive node (``name``: its address or id, for messages)."""

    name: str
    cpus: float
    gpus: float


def _fits(have: float, need: float) -> int:
    """How many requests of ``need`` fit into ``have`` (unbounded when nothing is needed)."""
    return 1 << 30 if need <= 0 else int(math.floor(have / need + _EPS))


def workers_per_node(node: NodeResources, cpus_per_worker: float, gpus_per_worker: float) -> int:
    """Identical workers of this size the node can host at once."""
    return min(_fits(node.cpus, cpus_per_worker), _fits(node.gpus, gpus_per_worker))


def live_nodes() -> list[NodeResources]:
    """Alive nodes of the Ray cluster this process is connected to."""
    return [NodeResources(str(n.get("NodeManagerAddress") or n.get("NodeID")),
                          float(n["Resources"].get("CPU", 0.0)), float(n["Resources"].get("GPU", 0.0)))
            for n in ray.nodes() if n.get("Alive")]


def check_feasible(num_workers: int, cpus_per_worker: float, gpus_per_worker: float) -> None:
    """:class:`InfeasibleRequest` unless the connected cluster can run ``num_workers`` workers of this size at once."""
    nodes = live_nodes()
    capacity = sum(workers_per_node(n, cpus_per_worker, gpus_per_worker) for n in nodes)
    if capacity >= num_workers:
        return
    total_cpus, total_gpus = sum(n.cpus for n in nodes), sum(n.gpus for n in nodes)
    lines = [f"The Ray cluster cannot run {num_workers} worker(s) of {cpus_per_worker:g} CPU + {gpus_per_worker:g} GPU "
             f"each: it has {total_cpus:g} CPUs and {total_gpus:g} GPUs ({len(nodes)} node(s)) and fits {capacity} "
             "such worker(s) at once."]
    if len(nodes) > 1:
        lines.append("per node: " + ", ".join(f"{n.name} {n.cpus:g} CPU/{n.gpus:g} GPU" for n in nodes))
    if gpus_per_worker > 0 and total_gpus == 0:
        lines.append("There are no GPUs: use --gpus-per-worker 0 to train on CPUs, or --address to join a "
                     "cluster with GPUs.")
    elif capacity > 0:
        lines.append(f"Lower --workers to {capacity}, or add nodes.")
    else:
        max_cpus = max((n.cpus for n in nodes), default=0.0)
        max_gpus = max((n.gpus for n in nodes), default=0.0)
        if cpus_per_worker > max_cpus + _EPS:
            lines.append(f"Each worker asks for {cpus_per_worker:g} CPUs but the largest node has {max_cpus:g}: "
                         "lower the CPUs per worker.")
        if gpus_per_worker > max_gpus + _EPS:
            lines.append(f"Each worker asks for {gpus_per_worker:g} GPUs but the largest node has {max_gpus:g}: "
                         f"lower --gpus-per-worker to at most {max_gpus:g}.")
    raise InfeasibleRequest(" ".join(lines))
