"""How many training trials the Ray cluster runs at once, checked before a sweep starts.

Tune reserves nothing for a trial's own process (:data:`TRIAL_RESOURCES`); its Ray Train workers reserve the CPUs
and GPUs, so more trials at once than the cluster has workers for would leave worker groups waiting for each other.
A node hosts ``workers_per_node`` workers (``sray.platform.train.resources``); a trial needs ``run.workers``.
"""

from __future__ import annotations

import os

import ray
import torch

from sray.platform.config.train_config import TrainConfig
from sray.platform.train.resources import InfeasibleRequest, NodeResources, live_nodes, workers_per_node

TRIAL_RESOURCES = {"memory": 1.0}
"""What Tune reserves for a training trial's own process, which only drives its job: one byte of memory (Tune
refuses an empty request; any CPU would be taken from the trial's own workers)."""


def expected_nodes() -> list[NodeResources]:
    """The nodes of the Ray cluster this process is connected to, or else of the local Ray that ``sray`` starts
    (``launcher.init_ray``: every CPU of this machine, its CUDA GPUs), known before it starts."""
    if ray.is_initialized():
        return live_nodes()
    return [NodeResources("this machine", float(os.cpu_count() or 1), float(torch.cuda.device_count()))]


def trials_at_once(cfg: TrainConfig, nodes: list[NodeResources]) -> int:
    """Trials of ``cfg``'s size the nodes host at once (0 when not even one fits)."""
    workers = sum(workers_per_node(n, cfg.run.cpus_per_worker, cfg.run.gpus_per_worker) for n in nodes)
    return workers // cfg.run.workers


def _size(cfg: TrainConfig) -> str:
    return f"{cfg.run.workers} worker(s) of {cfg.run.cpus_per_worker:g} CPU + {cfg.run.gpus_per_worker:g} GPU"


def plan_concurrency(requested: int, configs: list[TrainConfig], nodes: list[NodeResources]) -> int:
    """The number of trials to run at once on ``nodes``: ``requested`` if they fit that many trials of every
    size in ``configs``, as many as fit when ``requested`` is 0; :class:`InfeasibleRequest` naming the fix."""
    have = (f"{sum(n.cpus for n in nodes):g} CPUs and {sum(n.gpus for n in nodes):g} GPUs on {len(nodes)} "
            "node(s)")
    fits = [(trials_at_once(cfg, nodes), cfg) for cfg in configs]
    for n, cfg in fits:
        if n == 0:
            raise InfeasibleRequest(
                f"run.workers / run.cpus_per_worker / run.gpus_per_worker: a trial trains {_size(cfg)}, which the "
                f"cluster ({have}) cannot host at once; lower --workers, --set run.cpus_per_worker or "
                "--gpus-per-worker, or join a larger cluster with --address")
    fit, widest = min(fits, key=lambda pair: pair[0])
    if requested == 0:
        return fit
    if requested > fit:
        raise InfeasibleRequest(
            f"--max-concurrent {requested}: each trial trains {_size(widest)} and the cluster ({have}) fits {fit} "
            f"such trial(s) at once; use --max-concurrent {fit} (or 0 for as many as fit), fewer workers per trial "
            "(--workers), or fractional CPUs (--set run.cpus_per_worker=0.5)")
    return requested
