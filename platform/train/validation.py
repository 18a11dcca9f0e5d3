"""Validation during training (rank 0): held-out views of training scenes and zero-shot unseen scenes.

``val/*`` scores come from the held-out ``test`` views of the training scenes (sources from their
``train`` views); ``zeroshot/*`` from the unseen test scenes' ``test`` views with their fixed
``source`` views (the paper's generalization protocol). Logged against the step, they give the
paper's table of metrics against iterations. Both groups are made the same way,
:func:`validation_protocol` (logged once per run by the launcher: tag ``sray.protocol``, params
``protocol.*``); validation renders are strided (``data.held_out.stride``), so they carry no SSIM
unless that is 1, and use the fast render mode on those pixels unless ``data.held_out.render`` is ``full``
(:mod:`sray.platform.config.held_out_render`). One validation reads the shard manifest once and hands it down.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import torch
from torch import nn

from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.shards.manifest import Manifest, read_manifest
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.config.train_config import TrainConfig
from sray.platform.eval.scene_scoring import score_scene
from sray.platform.eval.view_scoring import ViewPrediction, sray_renderer
from sray.platform.viz.renders import render_panel

GROUPS = {"val": "train", "zeroshot": "test"}
"""Metric prefix -> scene role it is computed on."""


def validation_protocol(cfg: TrainConfig) -> EvalProtocol:
    """How ``val/*`` and ``zeroshot/*`` are made (``data.held_out``): its fixed sources (0: ``model.n_source``) ranked
    by the shards' neighbour rule, every ``stride``-th pixel, the model's ``model.inputs``, its render."""
    held_out = cfg.data.held_out
    return EvalProtocol.from_shards(Path(cfg.data.shards), held_out.sources(cfg.model.n_source), held_out.stride,
                                    cfg.model.inputs).rendered_by(held_out.fast())


def _mean(scores: list[dict[str, float]]) -> dict[str, float]:
    keys = scores[0].keys()
    return {k: sum(s[k] for s in scores) / len(scores) for k in keys}


def evaluate_group(net: nn.Module, cfg: TrainConfig, manifest: Manifest, role: str,
                   device: torch.device) -> tuple[dict[str, float], list[tuple[str, ViewPrediction]]]:
    """Scores averaged over the scenes of ``role`` (each scene scored from its own confusion matrix; the
    first ``data.val_scenes`` of them by name when that is set), and the rendered views (scene, prediction).
    Empty when no scene of that role has test views.
    ``manifest``: the parsed ``cfg.data.shards`` manifest (not read again here)."""
    per_scene, renders = [], []
    scenes = [(name, entry) for name, entry in sorted(manifest.scenes.items())
              if entry.meta.get("role") == role and entry.meta.get("splits", {}).get("test")]
    held_out = cfg.data.held_out
    fast = held_out.fast()
    for name, entry in scenes[:cfg.data.val_scenes or None]:
        samples = itertools.islice(make_eval_samples(Path(cfg.data.shards), name, split="test",
                                                     n_source=held_out.sources(cfg.model.n_source), manifest=manifest),
                                   cfg.data.val_views_per_scene)
        scored = score_scene(lambda s: sray_renderer(net, s, device, fast, cfg.runtime), samples, cfg.model.n_classes,
                             cfg.model.ignore_id, held_out.stride, cfg.runtime.chunk, device, fast)
        per_scene.append(scored.scores)
        renders += [(name, v) for v in scored.views]
    return (_mean(per_scene) if per_scene else {}), renders


def validate(net: nn.Module, cfg: TrainConfig, step: int, logger: Any, job_dir: Path,
             device: torch.device) -> dict[str, float]:
    """Run both validation groups, log their scores and one render panel each; returns the scores."""
    was_training = net.training
    net.eval()
    metrics: dict[str, float] = {}
    manifest = read_manifest(Path(cfg.data.shards))  # the one read of this validation
    class_names = next(iter(manifest.scenes.values())).meta["class_names"]
    try:
        for prefix, role in GROUPS.items():
            scores, renders = evaluate_group(net, cfg, manifest, role, device)
            metrics |= {f"{prefix}/{k}": v for k, v in scores.items()}
            if renders:
                scene, view = renders[0]
                png = job_dir / "renders" / f"{prefix}_step{step:07d}_{scene}_{view.query_id}.png"
                render_panel(view.pred_label.numpy(), view.gt_label.numpy(), view.pred_rgb.numpy(),
                             view.gt_rgb.numpy(), class_names, png, cfg.model.ignore_id,
                             title=f"{prefix} step {step}: {scene} view {view.query_id}")
                if logger is not None:
                    logger.log_image(png, artifact_path=f"renders/{prefix}")
    finally:
        net.train(was_training)
    if logger is not None and metrics:
        logger.log_metrics(metrics, step)
    return metrics
