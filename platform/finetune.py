"""One scene's finetune (the body of a fleet task): S-Ray from the shared model, or Semantic-NeRF from scratch.

Both methods train on the scene's loader pool (test scenes: ``source`` + ``finetune`` views; train
scenes: ``train`` minus held-out views) with the shared loss, and are scored on the held-out ``test``
views rendered from their fixed source views (``make_eval_samples``), every ``eval_every`` steps and
at step 0 (zero-shot S-Ray, untrained Semantic-NeRF). The score is the dataset-level mIoU (one
confusion matrix over the scene's held-out views). A finetune stops at the first of: ``patience``
evaluations without an improvement > ``min_delta`` (early stop), ``max_steps``, ``max_seconds`` of
training time. The best evaluated state is kept and stored as the scene artifact
(:mod:`sray.platform.scene_delta`). Sampling uses the scene's own near/far from the shard metadata.

Time: ``wall_s`` (curve and result) counts training time only (data, forward, backward, update);
evaluation is protocol overhead and is left out, so methods compare at equal training time.
Plain PyTorch, one process: autocast bf16 (CPU/CUDA) or fp16 with a GradScaler (CUDA).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from sray.data_tools.loader import make_eval_samples, make_train_loader
from sray.data_tools.loader_views import read_scene_views
from sray.data_tools.manifest import read_manifest
from sray.data_tools.scene import SceneMeta
from sray.model.losses import render_loss
from sray.model.rays import pixel_rays
from sray.model.semantic_nerf import SemanticNeRF, SemanticNeRFConfig, scene_box_from_cameras
from sray.model.sray import SRayModel
from sray.platform.evaluation import render_view, score_views, sray_renderer
from sray.platform.fleet_config import FleetConfig
from sray.platform.scene_delta import (NERF_ARTIFACT, SRAY_ARTIFACT, adapted_keys, adapted_state, apply_delta,
                                       model_bytes, save_semantic_nerf, save_sray_delta)
from sray.platform.train_state import model_from_checkpoint
from sray.platform.train_worker import NonFiniteTraining

RESULT_FILE = "result.json"
"""Per (scene, method) result, at ``<fleet>/scenes/<scene>/<method>/result.json`` (docs/CONTRACTS.md)."""
PROTOCOL = ("dataset-level mIoU over the scene's held-out test views (one confusion matrix per scene), "
            "each rendered from its fixed source views")
"""The protocol named in every result (``miou``; ``miou_per_image`` is the per-image protocol)."""


class InjectedFailure(RuntimeError):
    """Raised on purpose for scenes listed in ``FleetConfig.fail_scenes`` (a testing aid)."""


@dataclass(frozen=True)
class SceneJob:
    """What one fleet task needs (picklable)."""

    scene: str
    """Scene name in the shard manifest."""
    method: str
    """``sray`` or ``semantic-nerf``."""
    checkpoint: str
    """Shared S-Ray checkpoint folder (its config also sets the defaults both methods inherit)."""
    base_sha256: str
    """sha256 of the checkpoint's ``state.pt`` (recorded in S-Ray artifacts)."""
    shards: str
    """Shard folder (``manifest.json``)."""
    out_dir: str
    """``<fleet>/scenes/<scene>/<method>``: result.json and the scene artifact go here."""
    run: dict[str, str] | None
    """The child MLflow run's ``RunHandle`` fields (None: no tracking)."""
    attempt: int
    """1 for the first try, 2 for the first re-run, ..."""
    config: FleetConfig
    """The fleet's configuration."""


@dataclass
class SceneOutcome:
    """A finished finetune: the contract's result dict and the finetuned network (best state)."""

    result: dict[str, Any]
    model: nn.Module


class EarlyStopping:
    """Stop after ``patience`` evaluations in a row without beating the best by more than ``min_delta``.

    The first value (step 0) sets the baseline; NaN never improves.
    """

    def __init__(self, patience: int, min_delta: float) -> None:
        self.patience, self.min_delta = patience, min_delta
        self.best: float | None = None
        self.bad = 0

    def update(self, value: float) -> bool:
        """Record an evaluation; True if it is the new best."""
        first = self.best is None
        if first or (not math.isnan(value) and (math.isnan(self.best) or value > self.best + self.min_delta)):
            self.best, self.bad = value, 0
            return True
        self.bad += 1
        return False

    @property
    def should_stop(self) -> bool:
        """True once ``patience`` evaluations in a row failed to improve."""
        return self.bad >= self.patience


def autocast(device: torch.device, precision: str) -> contextlib.AbstractContextManager:
    """The autocast region of ``precision`` ("no", "bf16", "fp16") on ``device``."""
    dtype = {"bf16": torch.bfloat16, "fp16": torch.float16}.get(precision)
    return torch.autocast(device.type, dtype=dtype, enabled=dtype is not None)


def _rays(batch: dict[str, Any], device: torch.device) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """origins, dirs (R, 3) and the scene's near/far (R,) of a training sample, on ``device``."""
    origins, dirs = pixel_rays(batch["query_K"].to(device), batch["query_c2w"].to(device), batch["pixels"].to(device))
    near = torch.full((origins.shape[0],), float(batch["near"]), device=device)
    far = torch.full((origins.shape[0],), float(batch["far"]), device=device)
    return origins, dirs, near, far


class _Learner:
    """Optimiser, precision and the update rule shared by both methods."""

    def __init__(self, net: nn.Module, params: list[nn.Parameter], lr: float, grad_clip: float, precision: str,
                 device: torch.device) -> None:
        self.net, self.params, self.device, self.precision = net, params, device, precision
        self.grad_clip = grad_clip
        self.optimizer = torch.optim.Adam(params, lr=lr)
        self.scaler = torch.amp.GradScaler("cuda") if precision == "fp16" else None

    def update(self, loss: Tensor) -> bool:
        """Backward, clip and step; False (step skipped) when the loss or a gradient is not finite."""
        if self.scaler is not None:
            self.scaler.scale(loss).backward()
            self.scaler.unscale_(self.optimizer)
        else:
            loss.backward()
        grads = [p for p in self.params if p.grad is not None]
        norm = (torch.nn.utils.clip_grad_norm_(grads, self.grad_clip) if self.grad_clip > 0
                else torch.linalg.vector_norm(torch.stack([p.grad.norm() for p in grads])))
        finite = bool(torch.isfinite(norm)) and bool(torch.isfinite(loss.detach()))
        if self.scaler is not None:  # the scaler skips overflowing steps itself
            self.scaler.step(self.optimizer)
            self.scaler.update()
        elif finite:
            self.optimizer.step()
        self.optimizer.zero_grad(set_to_none=True)
        return finite


class SRayLearner(_Learner):
    """Trains only the modules ``adapt`` of the shared S-Ray model (the rest stays frozen)."""

    method = "sray"

    def __init__(self, net: SRayModel, adapt: tuple[str, ...], lr: float, grad_clip: float, precision: str,
                 device: torch.device) -> None:
        net = net.to(device).eval()
        self.adapt = tuple(adapt)
        keys = set(adapted_keys(net, adapt))
        params = [p for name, p in net.named_parameters() if name in keys]
        for name, p in net.named_parameters():
            p.requires_grad_(name in keys)
        self.encoder_frozen = not any(k.startswith("encoder.") for k in keys)
        super().__init__(net, params, lr, grad_clip, precision, device)

    def loss(self, batch: dict[str, Any]) -> tuple[Tensor, dict[str, Tensor]]:
        """Loss of one training sample (sources encoded without gradient while the encoder is frozen)."""
        origins, dirs, near, far = _rays(batch, self.device)
        with autocast(self.device, self.precision):
            with torch.no_grad() if self.encoder_frozen else contextlib.nullcontext():
                src = self.net.encode(batch["src_rgb"].to(self.device), batch["src_K"].to(self.device),
                                      batch["src_c2w"].to(self.device))
            out = self.net.render_rays(src, origins, dirs, near, far, stratified=True)
        return render_loss(out, batch["target_label"].to(self.device), batch["target_rgb"].to(self.device),
                           self.net.cfg)

    def renderer(self, sample: dict[str, Any]) -> Any:
        """Ray renderer bound to the sample's fixed source views."""
        return sray_renderer(self.net, sample, self.device)

    def snapshot(self) -> dict[str, Tensor]:
        """CPU copy of the adapted tensors."""
        return adapted_state(self.net, self.adapt)

    def restore(self, state: dict[str, Tensor]) -> None:
        """Put back a :meth:`snapshot`."""
        apply_delta(self.net, state, "snapshot")

    def save(self, out_dir: Path, job: SceneJob) -> Path:
        """Write the scene artifact (the adapted tensors as they are now + the base checksum)."""
        path = out_dir / SRAY_ARTIFACT
        save_sray_delta(path, self.snapshot(), job.base_sha256, self.adapt, job.scene)
        return path


class NeRFLearner(_Learner):
    """Trains a Semantic-NeRF of the scene from scratch (every parameter)."""

    method = "semantic-nerf"

    def __init__(self, net: SemanticNeRF, lr: float, grad_clip: float, precision: str, device: torch.device) -> None:
        net = net.to(device).eval()
        super().__init__(net, list(net.parameters()), lr, grad_clip, precision, device)

    def loss(self, batch: dict[str, Any]) -> tuple[Tensor, dict[str, Tensor]]:
        """Loss of one training sample's rays (its source views are not used)."""
        origins, dirs, near, far = _rays(batch, self.device)
        with autocast(self.device, self.precision):
            out = self.net.render_rays(origins, dirs, near, far, stratified=True)
        return render_loss(out, batch["target_label"].to(self.device), batch["target_rgb"].to(self.device),
                           self.net.cfg)

    def renderer(self, sample: dict[str, Any]) -> Any:
        """Ray renderer (deterministic samples)."""
        return lambda o, d, near, far: self.net.render_rays(o, d, near, far, stratified=False)

    def snapshot(self) -> dict[str, Tensor]:
        """CPU copy of the whole state dict."""
        return {k: v.detach().to("cpu", copy=True) for k, v in self.net.state_dict().items()}

    def restore(self, state: dict[str, Tensor]) -> None:
        """Put back a :meth:`snapshot`."""
        self.net.load_state_dict(state)

    def save(self, out_dir: Path, job: SceneJob) -> Path:
        """Write the scene artifact (the whole model as it is now: Semantic-NeRF shares nothing)."""
        path = out_dir / NERF_ARTIFACT
        save_semantic_nerf(path, self.net, job.scene)
        return path


def build_semantic_nerf(shards: Path, scene: str, n_classes: int, ignore_id: int, n_coarse: int, n_fine: int,
                        cfg: FleetConfig) -> SemanticNeRF:
    """A fresh Semantic-NeRF (seeded) whose scene box covers the frusta of all the scene's split views."""
    manifest = read_manifest(shards)
    entry = manifest.scenes[scene]
    meta = SceneMeta.from_json(entry.meta)
    views = read_scene_views(shards, entry)
    ids = [v for v in meta.view_ids if any(v in s for s in meta.splits.values())]
    K = torch.from_numpy(np.stack([views[v].K for v in ids]))  # (V, 3, 3)
    c2w = torch.from_numpy(np.stack([views[v].c2w for v in ids]))  # (V, 4, 4)
    center, scale = scene_box_from_cameras(K, c2w, tuple(entry.image_size), meta.near, meta.far)
    nerf = cfg.nerf
    torch.manual_seed(cfg.finetune.seed)
    return SemanticNeRF(SemanticNeRFConfig(
        n_classes=n_classes, pos_freqs=nerf.pos_freqs, dir_freqs=nerf.dir_freqs, depth=nerf.depth, width=nerf.width,
        skip_layer=nerf.skip_layer, n_coarse=n_coarse, n_fine=n_fine, ignore_id=ignore_id, chunk=cfg.finetune.eval_chunk,
        scene_center=center, scene_scale=scale))


@torch.no_grad()
def evaluate(learner: Any, samples: list[dict[str, Any]], cfg: FleetConfig, n_classes: int,
             ignore_id: int) -> dict[str, float]:
    """Held-out scores (``score_views`` keys) of the learner's current state."""
    ft = cfg.finetune
    with autocast(learner.device, ft.precision):
        views = [render_view(learner.renderer(s), s, ft.eval_stride, ft.eval_chunk, learner.device) for s in samples]
    return score_views(views, n_classes, ignore_id)


def write_result(out_dir: Path, result: dict[str, Any]) -> Path:
    """Write ``result.json`` atomically (temp name, then rename)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / RESULT_FILE
    tmp = out_dir / f".tmp-{RESULT_FILE}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tmp.write_text(json.dumps(result, indent=1) + "\n")
    os.replace(tmp, path)
    return path


def finetune_scene(job: SceneJob, logger: Any = None) -> SceneOutcome:
    """Finetune one (scene, method), write its artifact and ``result.json``; ``logger``: a RunLogger or None."""
    from sray.platform.progress import make_progress

    cfg, ft = job.config, job.config.finetune
    if job.scene in cfg.fail_scenes:
        raise InjectedFailure(f"scene {job.scene!r} is listed in fail_scenes (testing aid); attempt {job.attempt}")
    use_cuda = cfg.gpus_per_task > 0 and torch.cuda.is_available()
    device = torch.device("cuda" if use_cuda else "cpu")
    shards, out_dir = Path(job.shards), Path(job.out_dir)
    base, train_cfg = model_from_checkpoint(job.checkpoint)
    n_classes, ignore_id = train_cfg.model.n_classes, train_cfg.model.ignore_id
    manifest = read_manifest(shards)
    if job.scene not in manifest.scenes:
        raise ValueError(f"{shards}/manifest.json: no scene {job.scene!r}")
    class_names = manifest.scenes[job.scene].meta["class_names"]
    if len(class_names) != n_classes:
        raise ValueError(f"{shards}/manifest.json: scene {job.scene!r} has {len(class_names)} classes, the checkpoint "
                         f"{job.checkpoint} predicts {n_classes}; use shards of the checkpoint's label space")
    full_bytes = model_bytes(base)
    if job.method == "sray":
        learner: Any = SRayLearner(base, ft.adapt, ft.lr, ft.grad_clip, ft.precision, device)
        n_source = ft.n_source or train_cfg.model.n_source
        top_k = ft.top_k or min(train_cfg.data.top_k, int(manifest.neighbours["k"]))
    elif job.method == "semantic-nerf":
        net = build_semantic_nerf(shards, job.scene, n_classes, ignore_id, cfg.nerf.n_coarse or train_cfg.model.n_coarse,
                                  cfg.nerf.n_fine or train_cfg.model.n_fine, cfg)
        learner = NeRFLearner(net, cfg.nerf.lr, ft.grad_clip, ft.precision, device)
        n_source, top_k = 1, 1  # only the query's rays are used
    else:
        raise ValueError(f"method {job.method!r}: use one of 'sray', 'semantic-nerf'")
    loader = make_train_loader(shards, n_source=n_source, top_k=max(top_k, n_source),
                               rays_per_batch=ft.rays_per_batch or train_cfg.data.rays_per_batch,
                               batches_per_epoch=ft.eval_every, rank=0, world_size=1, num_workers=0, seed=ft.seed,
                               scenes=[job.scene])
    samples = list(make_eval_samples(shards, job.scene, split="test", n_source=ft.eval_n_source))
    if logger is not None:
        logger.log_params(cfg.to_dict() | {"scene": job.scene, "method": job.method, "checkpoint": job.checkpoint})
        logger.log_metrics({"attempt": job.attempt}, 0)

    curve: list[dict[str, float]] = []
    stopper = EarlyStopping(ft.patience, ft.min_delta)
    train_s, step, reason = 0.0, 0, "max_steps"
    best_state, best_point = learner.snapshot(), None

    def evaluate_now() -> None:
        nonlocal best_state, best_point
        scores = evaluate(learner, samples, cfg, n_classes, ignore_id)
        point = {"step": step, "wall_s": train_s, "miou": scores["miou"], "miou_per_image": scores["miou_per_image"],
                 "psnr": scores["psnr"]}
        curve.append(point)
        if stopper.update(scores["miou"]):
            best_state, best_point = learner.snapshot(), point
        if logger is not None:
            logger.log_metrics({f"heldout/{k}": v for k, v in scores.items()} | {"heldout/train_s": train_s}, step)

    bar = make_progress(True, total=ft.max_steps, desc=f"{job.scene}/{job.method}")
    evaluate_now()
    nonfinite, window = 0, []
    try:
        while step < ft.max_steps:
            start = time.perf_counter()
            if step % ft.eval_every == 0:
                batches = iter(loader)  # one loader epoch = eval_every samples
            torch.manual_seed((ft.seed * 1_000_003 + step) % (2**63 - 1))
            loss, terms = learner.loss(next(batches))
            finite = learner.update(loss)
            train_s += time.perf_counter() - start
            step += 1
            bar.update(1)
            nonfinite = 0 if finite else nonfinite + 1
            if nonfinite >= ft.max_nonfinite_in_row:
                raise NonFiniteTraining(f"{job.scene}/{job.method}: {nonfinite} steps in a row had a non-finite loss "
                                        f"or gradient (last at step {step}); lower finetune.lr or use precision no")
            if finite:
                window.append(float(loss.detach()))
            out_of_time = 0 < ft.max_seconds <= train_s
            if step % ft.eval_every == 0 or step == ft.max_steps or out_of_time:
                if logger is not None and window:
                    logger.log_metrics({"train/loss": sum(window) / len(window), "train/psnr": float(terms["psnr"])}, step)
                window = []
                evaluate_now()
                if stopper.should_stop:
                    reason = "patience"
                    break
            if out_of_time:
                reason = "max_seconds"
                break
    finally:
        bar.close()
    learner.restore(best_state)
    artifact = learner.save(out_dir, job)
    best_point = best_point or curve[0]
    result = {
        "scene": job.scene, "method": job.method, "status": "finished", "error": None, "attempts": job.attempt,
        "steps_used": step, "max_steps": ft.max_steps, "stopped_early": reason == "patience", "wall_s": train_s,
        "miou_before": curve[0]["miou"], "miou_after": best_point["miou"], "psnr_after": best_point["psnr"],
        "artifact_bytes": artifact.stat().st_size, "full_checkpoint_bytes": full_bytes,
        "child_run_id": job.run["run_id"] if job.run else None, "protocol": PROTOCOL, "curve": curve,
    }
    write_result(out_dir, result)
    if logger is not None:
        logger.log_metrics({"result/steps_used": step, "result/miou_after": result["miou_after"],
                            "result/best_step": best_point["step"], "result/stopped_early": float(reason == "patience"),
                            "result/artifact_bytes": result["artifact_bytes"], "result/train_s": train_s}, step)
        logger.log_artifact(out_dir / RESULT_FILE)
        logger.log_artifact(artifact, "scene_artifact")
    return SceneOutcome(result, learner.net)


def run_scene_job(job: SceneJob) -> dict[str, Any]:
    """The fleet task body: :func:`finetune_scene` logging into the job's child run; returns the result.

    The child run is marked FINISHED on success and FAILED when this attempt raises (a later
    successful re-run marks it FINISHED again).
    """
    from sray.platform.tracking import RunHandle
    from sray.platform.tracking_logger import RunLogger

    if job.run is None:
        return finetune_scene(job).result
    with RunLogger(RunHandle(**job.run)) as logger:
        return finetune_scene(job, logger).result
