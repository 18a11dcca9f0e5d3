"""One scene's finetune (a fleet task): evaluated every ``eval_every`` steps, its best state stored as the artifact."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import ray
import torch
from torch import nn

from sray.data_tools.atomic import atomic_write_json
from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.shard_loader import make_eval_samples, make_train_loader
from sray.data_tools.shards.manifest import read_manifest
from sray.model.config import SRayConfig
from sray.model.fast_render import FastRender
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.common.fault_hook import fail_if_listed
from sray.platform.common.progress import ThroughputWindow, make_progress, progress_postfix
from sray.platform.config.fleet_config import FleetConfig
from sray.platform.eval.view_scoring import score_scene
from sray.platform.finetune.learners import Learner
from sray.platform.finetune.methods.method import SceneContext
from sray.platform.finetune.methods.registry import get_method
from sray.platform.finetune.scene_artifacts import model_bytes
from sray.platform.finetune.step_budget import StepClock, time_limit_reached
from sray.platform.render.flythrough import Flythrough
from sray.platform.render.plan import plan_flythrough
from sray.platform.render.tracked import ARTIFACT_PATH, log_flythrough
from sray.platform.tracking.registry import open_logger
from sray.platform.tracking.tracker import RunHandle, RunLogger
from sray.platform.train.step import NonFiniteTraining, step_seed

RESULT_FILE = "result.json"
"""Per (scene, method) result, at ``<fleet>/scenes/<scene>/<method>/result.json`` (docs/CONTRACTS.md)."""


@dataclass(frozen=True)
class SceneTask:
    """What one fleet task needs (picklable)."""

    scene: str
    method: str
    checkpoint: str
    """Shared S-Ray checkpoint folder (its config also sets the defaults the methods inherit)."""
    base_sha256: str
    shards: str
    out_dir: str
    """``<fleet>/scenes/<scene>/<method>``: result.json and the scene artifact go here."""
    run: RunHandle | None
    """The pair's child run (None: no tracking)."""
    attempt: int
    """1 for the first try, 2 for the first re-run, ..."""
    config: FleetConfig
    clip_frames: int = 0
    """Frames of the fly-through rendered before and after the finetune (0: none)."""


@dataclass
class SceneOutcome:
    """A finished finetune: the contract's result dict and the finetuned network (best state)."""

    result: dict[str, Any]
    model: nn.Module


class EarlyStopping:
    """Stop after ``patience`` evaluations in a row not beating the best by ``min_delta`` (NaN never improves)."""

    def __init__(self, patience: int, min_delta: float) -> None:
        self.patience, self.min_delta = patience, min_delta
        self.best: float | None = None
        self.bad = 0

    def update(self, value: float) -> bool:
        """Record an evaluation; True if it is the new best."""
        best = self.best
        if best is None or (not math.isnan(value) and (math.isnan(best) or value > best + self.min_delta)):
            self.best, self.bad = value, 0
            return True
        self.bad += 1
        return False

    @property
    def should_stop(self) -> bool:
        """True once ``patience`` evaluations in a row failed to improve."""
        return self.bad >= self.patience


@torch.no_grad()
def evaluate(learner: Learner, samples: list[EvalSample], cfg: FleetConfig, n_classes: int,
             ignore_id: int) -> dict[str, float]:
    """Held-out scores (``score_views`` keys) of the learner's current state (``score_scene``)."""
    ft = cfg.finetune
    with learner.inference(), learner.step.autocast():
        return score_scene(learner.renderer, samples, n_classes, ignore_id, ft.held_out.stride, ft.eval_chunk,
                           learner.device, learner.fast).scores


def write_result(out_dir: Path, result: dict[str, Any]) -> None:
    """Write ``result.json`` atomically."""
    atomic_write_json(out_dir / RESULT_FILE, result)


def scene_protocol(task: SceneTask, shared: SRayConfig, fast: FastRender | None = None) -> EvalProtocol:
    """How the held-out scores are made (``finetune.held_out``, the method's inputs, ``fast`` or a full render)."""
    ft, method = task.config.finetune, get_method(task.method)
    if method.uses_sources:
        inputs = (method.inputs, "") if method.inputs else (shared.inputs, "")  # (test, training)
        n_source = ft.held_out.sources(shared.n_source)
        return EvalProtocol.from_shards(Path(task.shards), n_source, ft.held_out.stride, *inputs).rendered_by(fast)
    return EvalProtocol.without_sources(ft.held_out.stride)


def _prepare(task: SceneTask,
             device: torch.device) -> tuple[Learner, Any, list[EvalSample], tuple[int, int, int, SRayConfig]]:
    """The learner, training loader, held-out samples and (classes, ignore id, shared model bytes and config)."""
    ft, shards = task.config.finetune, Path(task.shards)
    method = get_method(task.method)
    base, train_cfg = model_from_checkpoint(task.checkpoint)
    n_classes, ignore_id = train_cfg.model.n_classes, train_cfg.model.ignore_id
    manifest = read_manifest(shards)
    if task.scene not in manifest.scenes:
        raise ValueError(f"{shards}/manifest.json: no scene {task.scene!r}")
    class_names = manifest.scenes[task.scene].meta["class_names"]
    if len(class_names) != n_classes:
        raise ValueError(f"{shards}/manifest.json: scene {task.scene!r} has {len(class_names)} classes, the checkpoint "
                         f"{task.checkpoint} predicts {n_classes}; use shards of the checkpoint's label space")
    full_bytes = model_bytes(base)
    setup = method.build(SceneContext(
        scene=task.scene, shards=shards, base=base, base_sha256=task.base_sha256, train_cfg=train_cfg, cfg=task.config,
        n_classes=n_classes, ignore_id=ignore_id, stored_neighbours=int(manifest.neighbours["k"]), device=device))
    loader = make_train_loader(shards, n_source=setup.n_source, top_k=max(setup.top_k, setup.n_source), rank=0,
                               rays_per_batch=ft.rays_per_batch or train_cfg.data.rays_per_batch, num_workers=0,
                               batches_per_epoch=ft.eval_every, world_size=1, seed=ft.seed, scenes=[task.scene],
                               source_labels=setup.source_labels)
    samples = list(make_eval_samples(shards, task.scene, n_source=ft.held_out.sources(train_cfg.model.n_source)))
    return setup.learner, loader, samples, (n_classes, ignore_id, full_bytes, train_cfg.model)


def render_clip(fly: Flythrough, stage: str, learner: Learner, out_dir: Path, logger: RunLogger | None) -> None:
    """Render the fly-through of ``stage`` with the learner's state, as held-out views, into ``flythrough_<stage>/``."""
    with learner.inference(), learner.step.autocast():
        result = fly.render(out_dir / f"flythrough_{stage}", learner.device, label=f"{stage} finetuning",
                            progress=False)
    if logger is not None:
        log_flythrough(logger, result["files"], f"{ARTIFACT_PATH}/{stage}")


def finetune_scene(task: SceneTask, logger: RunLogger | None = None) -> SceneOutcome:
    """Finetune one (scene, method), write its artifact and ``result.json``; ``logger``: the child run's or None."""
    cfg, ft = task.config, task.config.finetune
    fail_if_listed(task.scene, task.attempt)
    use_cuda = cfg.gpus_per_task > 0 and torch.cuda.is_available()
    device = torch.device("cuda" if use_cuda else "cpu")
    if use_cuda:
        torch.cuda.reset_peak_memory_stats(device)  # this task's peak, not an earlier task's in the same worker
    out_dir = Path(task.out_dir)
    learner, loader, samples, (n_classes, ignore_id, full_bytes, shared) = _prepare(task, device)
    protocol = scene_protocol(task, shared, learner.fast)
    fly = (Flythrough(learner.net, plan_flythrough(Path(task.shards), task.scene, n_frames=task.clip_frames),
                      ft.held_out.sources(learner.net.cfg.n_source), ft.held_out.fast())
           if task.clip_frames and get_method(task.method).clips else None)
    if logger is not None:
        logger.log_params(asdict(cfg) | {"scene": task.scene, "method": task.method, "checkpoint": task.checkpoint,
                                         "protocol": protocol.to_json()})
        logger.log_metrics({"attempt": task.attempt}, 0)

    curve: list[dict[str, float]] = []
    stopper = EarlyStopping(ft.patience, ft.min_delta)
    clock, step, reason = StepClock(), 0, "max_steps"
    best_state, best_point = learner.snapshot(), None

    def evaluate_now() -> None:
        nonlocal best_state, best_point
        scores = evaluate(learner, samples, cfg, n_classes, ignore_id)
        point = {"step": step, "wall_s": clock.wall_s} | {k: scores[k] for k in ("miou", "miou_per_image", "psnr")}
        curve.append(point)
        if stopper.update(scores["miou"]):
            best_state, best_point = learner.snapshot(), point
        if logger is not None:
            logger.log_metrics({f"heldout/{k}": v for k, v in (scores | {"train_s": clock.wall_s}).items()}, step)

    if fly is not None:
        render_clip(fly, "before", learner, out_dir, logger)
    bar = make_progress(True, total=ft.max_steps, desc=f"{task.scene}/{task.method}")
    throughput = ThroughputWindow(loader.dataset.rays, 1, device)
    evaluate_now()
    window: list[torch.Tensor] = []
    try:
        while step < ft.max_steps:
            with clock.step():
                if step % ft.eval_every == 0:
                    batches = iter(loader)  # one loader epoch = eval_every samples
                torch.manual_seed(step_seed(ft.seed, 0, step))
                loss, terms = learner.loss(throughput.next_batch(batches))
                try:
                    outcome = learner.step(loss)
                except NonFiniteTraining as err:
                    raise NonFiniteTraining(f"{task.scene}/{task.method} at step {step}: {err}") from None
            step += 1
            throughput.step_done()
            bar.update(1)
            if outcome.applied:
                window.append(loss.detach())
            out_of_time = time_limit_reached(ft, clock)
            if step % ft.eval_every == 0 or step == ft.max_steps or out_of_time:
                figures = throughput.report()
                if window:
                    mean_loss = float(torch.stack(window).mean())
                    bar.set_postfix(**progress_postfix(mean_loss, figures))
                    if logger is not None:
                        logger.log_metrics({"train/loss": mean_loss, "train/psnr": float(terms["psnr"])}
                                           | {f"train/{k}": v for k, v in figures.items()}, step)
                window = []
                evaluate_now()
                if stopper.should_stop and step < ft.max_steps:
                    reason = "patience"
                    break
            if out_of_time:
                reason = out_of_time
                break
    finally:
        bar.close()
    learner.restore(best_state)
    learner.net.requires_grad_(True)  # the returned model is in the state of a reloaded one (see Learner.inference)
    if fly is not None:
        render_clip(fly, "after", learner, out_dir, logger)
    artifact = out_dir / get_method(task.method).artifact_file
    learner.save(artifact, task.scene)
    best_point = best_point or curve[0]
    result = {
        "scene": task.scene, "method": task.method, "status": "finished", "error": None, "attempts": task.attempt,
        "steps_used": step, "max_steps": ft.max_steps, "stopped_early": reason == "patience", "stop_reason": reason,
        "wall_s": clock.wall_s, "cpu_s": clock.cpu_s, "miou_before": curve[0]["miou"], "miou_after": best_point["miou"],
        "psnr_after": best_point["psnr"], "artifact_bytes": artifact.stat().st_size,
        "full_checkpoint_bytes": full_bytes, "child_run_id": task.run.run_id if task.run else None,
        "protocol": protocol.to_json(), "curve": curve,
        "gpu_peak_bytes": torch.cuda.max_memory_allocated(device) if use_cuda else None}
    write_result(out_dir, result)
    if logger is not None:
        logged = ("steps_used", "miou_before", "miou_after", "psnr_after", "artifact_bytes")
        logger.log_metrics({f"result/{k}": result[k] for k in logged} | {
            "result/best_step": best_point["step"], "result/stopped_early": float(reason == "patience"),
            "result/train_s": clock.wall_s, "result/train_cpu_s": clock.cpu_s}, step)
        logger.log_artifact(out_dir / RESULT_FILE)
        logger.log_artifact(artifact, "scene_artifact")
    return SceneOutcome(result, learner.net)


def run_scene_task(task: SceneTask) -> dict[str, Any]:
    """The fleet's Ray task body: :func:`finetune_scene` into the child run; its result with the Ray node. Torch gets
    the task's CPUs as threads, set only when that differs (docs/performance.md, "`torch.set_num_threads`...")."""
    threads = max(1, int(task.config.cpus_per_task))
    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)

    if task.run is None:
        outcome = finetune_scene(task)
    else:
        with open_logger(task.run) as logger:
            outcome = finetune_scene(task, logger)
    result = outcome.result | {"node_id": ray.get_runtime_context().get_node_id()}
    write_result(Path(task.out_dir), result)
    return result
