"""Validation during training (rank 0): ``val/*`` on training scenes' held-out views, ``zeroshot/*`` on test scenes."""

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
from sray.platform.eval.view_scoring import ViewPrediction, score_scene, sray_renderer
from sray.platform.viz.renders import render_panel

GROUPS = {"val": "train", "zeroshot": "test"}
"""Metric prefix -> scene role it is computed on."""


def validation_protocol(cfg: TrainConfig) -> EvalProtocol:
    """How ``val/*`` and ``zeroshot/*`` are made (``data.held_out``, ``model.inputs``, what its training read)."""
    held_out = cfg.data.held_out
    return EvalProtocol.from_shards(Path(cfg.data.shards), held_out.sources(cfg.model.n_source), held_out.stride,
                                    cfg.model.inputs).rendered_by(held_out.fast())


def evaluate_group(net: nn.Module, cfg: TrainConfig, manifest: Manifest, role: str,
                   device: torch.device) -> tuple[dict[str, float], list[tuple[str, ViewPrediction]]]:
    """Mean scores over the scenes of ``role`` (the first ``data.val_scenes``) and the rendered (scene, view)s."""
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
    means = {k: sum(s[k] for s in per_scene) / len(per_scene) for k in per_scene[0]} if per_scene else {}
    return means, renders


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
