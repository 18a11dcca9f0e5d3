"""The function every Ray Train worker runs: an Accelerate training loop over the shard loader."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import ray.train
import torch
from accelerate import Accelerator

from sray.platform.checkpoints.folders import CheckpointManager, load_checkpoint, read_meta
from sray.platform.common.fault_hook import active_faults, hold_if_due, kill_if_due
from sray.platform.common.model_input import ray_batch
from sray.platform.common.progress import ThroughputWindow, make_progress, peak_memory_mb, progress_postfix
from sray.platform.config.train_config import TrainConfig
from sray.platform.tracking.registry import open_logger
from sray.platform.tracking.tracker import RunHandle
from sray.platform.train.cpu_clock import CpuClock
from sray.platform.train.job_loader import job_loader
from sray.platform.train.state import (FIRST_COUNTERS, budget_lr_factor, build_training, restore_training,
                                       training_state)
from sray.platform.train.step import TrainStep, step_seed
from sray.platform.train.validation import validate

STOP_FILE = "STOP"
"""A file of this name in the job folder asks every worker to checkpoint and stop (Ctrl-C)."""
UNSENT_METRICS = "unsent_metrics"
"""Checkpoint entry: ``[key, value, step]`` of each metric not delivered by then, logged again on a restart."""


def parameter_divergence(model: torch.nn.Module, world: int) -> float:
    """Largest difference between ranks of a parameter fingerprint (0 unless DDP replicas diverged; all ranks call)."""
    with torch.no_grad():
        fingerprint = torch.stack([p.detach().float().sum() + p.detach().float().abs().sum()
                                   for p in model.parameters()])  # on the params' device (NCCL needs CUDA tensors)
    if world == 1:
        return 0.0
    gathered = [torch.empty_like(fingerprint) for _ in range(world)]
    torch.distributed.all_gather(gathered, fingerprint)
    return float(torch.stack(gathered).amax(0).sub(torch.stack(gathered).amin(0)).abs().max())


def to_ray_checkpoint(directory: Path) -> ray.train.Checkpoint:
    """A ``ray.train.Checkpoint`` of one checkpoint folder (pass it to ``ray.train.report``)."""
    read_meta(directory)
    return ray.train.Checkpoint.from_directory(str(Path(directory).resolve()))


def from_ray_checkpoint(checkpoint: ray.train.Checkpoint, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """The state dict inside a ``ray.train.Checkpoint`` (e.g. from ``ray.train.get_checkpoint()``)."""
    with checkpoint.as_directory() as directory:
        read_meta(Path(directory))
        return load_checkpoint(Path(directory), map_location)


def train_worker(payload: dict[str, Any]) -> None:
    """Ray Train entry point. ``payload`` = {"config": TrainConfig.to_dict(), "run": RunHandle fields}."""
    cfg = TrainConfig.from_dict(payload["config"])
    ctx = ray.train.get_context()
    rank, world = ctx.get_world_rank(), ctx.get_world_size()
    job_dir, faults = cfg.job_dir(), active_faults()
    # Accelerate places the model and wraps it for DDP; autocast and loss scaling are the shared TrainStep's
    use_cuda = cfg.run.gpus_per_worker > 0 and torch.cuda.is_available()
    accelerator = Accelerator(mixed_precision="no", cpu=not use_cuda)
    device = accelerator.device
    model, optimizer, scheduler = build_training(cfg)
    start, best, counters = 0, None, dict(FIRST_COUNTERS)
    # a restarted worker group resumes from Ray's last checkpoint, `--resume NAME` from the job's latest folder
    resumed = ray.train.get_checkpoint()
    state = (from_ray_checkpoint(resumed) if resumed is not None
             else load_checkpoint(Path(payload["resume_from"])) if payload.get("resume_from") else None)
    if state is not None:
        start, best, counters = restore_training(state, model.net, optimizer, scheduler)
        if rank == 0:
            how = "a restarted worker group" if resumed is not None else "--resume"
            print(f"[sray] resumed at step {start} ({how})", flush=True)
    model, optimizer = accelerator.prepare(model, optimizer)
    train_step = TrainStep(list(model.parameters()), optimizer, cfg.optim.grad_clip, cfg.run.precision, device,
                           cfg.optim.max_nonfinite_in_row, world)
    train_step.skipped_total = counters["skipped_steps"]
    if state is not None and train_step.scaler is not None and "scaler" in state:
        train_step.scaler.load_state_dict(state["scaler"])

    # CPU seconds of every rank and its loader processes, across resumes (optim.cpu_seconds budgets them)
    clock, cpu_total = CpuClock(counters["cpu_seconds"] / world), counters["cpu_seconds"]
    # rank 0's wall seconds since the set-up, across resumes (NaN stays NaN: unknown, FIRST_COUNTERS)
    wall_start, wall_before = time.perf_counter(), counters["wall_seconds"]
    manager = CheckpointManager(job_dir / "checkpoints", keep_last=cfg.run.keep_checkpoints)
    logger = open_logger(RunHandle(**payload["run"])) if rank == 0 else None
    # the first worker of each node records that node's system metrics into the job's run
    node_logger = (logger or open_logger(RunHandle(**payload["run"]))) if ctx.get_local_rank() == 0 else None
    stop_watching = (node_logger.watch_system(f"node{ctx.get_node_rank()}", cfg.run.system_metrics_s)
                     if node_logger is not None and cfg.run.system_metrics_s > 0 else lambda: None)
    if logger is not None and start == 0:
        logger.log_params(cfg.to_dict())
    if logger is not None and state is not None:
        for key, value, logged_at in state.get(UNSENT_METRICS, []):
            logger.log_metrics({key: value}, logged_at)  # the store missed them before the checkpoint
    # epoch e's stream depends only on (seed, e, rank): a resumed job sees the batches an uninterrupted one would
    epoch_len = cfg.data.epoch_steps or cfg.run.ckpt_every
    loader = job_loader(cfg, rank, world, epoch_len)

    def batches_from(step_at: int) -> Any:
        loader.set_epoch(step_at // epoch_len)
        stream = iter(loader)
        for _ in range(step_at % epoch_len):
            next(stream)
        return stream

    batches = batches_from(start)
    bar = make_progress(rank == 0, total=cfg.optim.steps, initial=start, desc=cfg.run.name)

    def checkpoint_and_report(step_done: int, metrics: dict[str, float]) -> None:
        """Every rank reports; rank 0 flushes metrics and saves, with the metrics it could not deliver."""
        divergence = parameter_divergence(model, world)
        if rank == 0:
            logger.log_metrics({"ddp/param_divergence": divergence}, step_done)
            logger.flush(force=True)
            counters["skipped_steps"], counters["cpu_seconds"] = train_step.skipped_total, cpu_total
            counters["wall_seconds"] = wall_before + time.perf_counter() - wall_start
            counters["peak_memory_mb"] = max(counters["peak_memory_mb"], peak_memory_mb(device))
            state = training_state(accelerator.unwrap_model(model).net, optimizer, scheduler, train_step.scaler,
                                   step_done, cfg, best, counters)
            state[UNSENT_METRICS] = [list(m) for m in logger.unsent_metrics()]  # store unreachable now
            path = manager.save(state, step_done, metrics.get("val/miou"))
            ray.train.report(metrics, checkpoint=to_ray_checkpoint(path))
        else:
            ray.train.report(metrics)

    budget = cfg.optim.cpu_seconds

    def follow_cpu_budget(next_step: int) -> None:
        """With a CPU budget, set the next step's learning rate (``budget_lr_factor``)."""
        if budget > 0:
            factor = budget_lr_factor(cfg.optim, next_step, cpu_total)
            for group in optimizer.param_groups:
                group["lr"] = group["initial_lr"] * factor

    window_terms, term_names = [], None
    throughput = ThroughputWindow(cfg.data.rays_per_batch, world, device)
    step = start
    follow_cpu_budget(start)
    try:
        while step < cfg.optim.steps:
            kill_if_due(faults, step, rank, job_dir, before_exit=lambda: logger.flush(force=True))
            hold_if_due(faults, step, rank, job_dir, lambda: {"node_id": ray.get_runtime_context().get_node_id()})

            if step % epoch_len == 0 and step != start:
                batches = batches_from(step)
            sample = throughput.next_batch(batches).to(device, non_blocking=True)
            torch.manual_seed(step_seed(cfg.run.seed, rank, step))
            model.train()
            with train_step.autocast():  # the first optim.warmup_2d_steps steps train on source labels only
                loss, terms = model(ray_batch(sample), sample.target_label, sample.target_rgb,
                                    render=step >= cfg.optim.warmup_2d_steps)
            if step == faults.nan_at_step:
                loss = loss * float("nan")
            stop_asked = (job_dir / STOP_FILE).exists() or step + 1 == faults.stop_after_step
            outcome = train_step(loss, stop_requested=stop_asked, cpu_seconds=clock.seconds())
            cpu_total = outcome.cpu_seconds
            scheduler.step()
            follow_cpu_budget(step + 1)
            finished = step + 1 == cfg.optim.steps or (budget > 0 and cpu_total >= budget)
            if outcome.applied:
                if term_names != [*terms, "loss"]:  # a new set of terms (the 2D warm-up ended) opens a new window
                    term_names, window_terms = [*terms, "loss"], []
                window_terms.append(torch.stack([*(terms[k].float() for k in term_names[:-1]), loss.detach().float()]))
            step += 1
            throughput.step_done()
            bar.update(1)

            if rank == 0 and (step % cfg.run.log_every == 0 or finished):
                figures = throughput.report()
                means = (dict(zip(term_names, torch.stack(window_terms).mean(0).tolist()))
                         if window_terms else {})  # one read of the whole window's terms
                logger.log_metrics({f"train/{k}": v for k, v in means.items()} | {
                    "train/lr": optimizer.param_groups[0]["lr"], "train/grad_norm": float(outcome.grad_norm),
                    "train/cpu_seconds": cpu_total, "train/skipped_steps": train_step.skipped_total}
                    | {f"train/{k}": v for k, v in figures.items()}, step)
                spent = {"cpu_budget": f"{cpu_total / budget:.0%}"} if budget > 0 else {}  # the budget that stops it
                bar.set_postfix(**progress_postfix(means.get("loss", float("nan")), figures), **spent)
                window_terms = []
            metrics: dict[str, float] = {"step": step}
            if rank == 0 and (step % cfg.run.val_every == 0 or finished):
                metrics |= validate(accelerator.unwrap_model(model).net, cfg, step, logger, job_dir, device)
                miou = metrics.get("val/miou")
                if miou is not None and (best is None or miou > best):
                    best = miou
            if outcome.stop:  # asked by a STOP file on any rank (all ranks read the same flag)
                checkpoint_and_report(step, metrics | {"stopped": 1.0})
                if rank == 0:
                    print(f"[sray] stopped at step {step}; resume with: sray train --resume {cfg.run.name}", flush=True)
                return
            if step % cfg.run.ckpt_every == 0 or finished:
                checkpoint_and_report(step, metrics)
            if finished:
                break
        if rank == 0:
            final = manager.best() or manager.latest()
            if cfg.run.register_model and final is not None:
                logger.register_model(final, cfg.run.register_model, alias="best")
            print(f"[sray] finished {step} steps; best checkpoint: {final}", flush=True)
    finally:
        bar.close()
        stop_watching()
        if logger is not None:
            logger.drain()  # a tracking server restarting now still gets every metric
