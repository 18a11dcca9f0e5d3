"""One point of the suite for a zero-shot row: a method's pretrained model, as its ``eval_model`` builds it for
``sray eval`` (:class:`~sray.platform.eval.eval_model.EvalModel`), renders the held-out views of the unseen test
scenes from the sources a spec picks, and is scored.

With no perturbation, ``n_source`` protocol sources, fp32 and the same stride, a point reproduces
``sray eval``'s dataset-level mIoU and PSNR exactly: the sources are the query's top-ranked
neighbours in the ``source`` split, each view is rendered by the model's own renderer and the scene's views are
scored by ``sray eval``'s loop (:func:`~sray.platform.eval.scene_scoring.score_scene`, ``chunk``-ray passes, one
confusion matrix per scene) and scenes are averaged unweighted.
"""

from __future__ import annotations

import contextlib
from typing import Any

import torch

from sray.platform.eval.eval_model import EvalModel
from sray.platform.eval.scene_scoring import score_scene
from sray.platform.eval.view_scoring import predict_view
from sray.platform.stability.output_watch import OutputWatch
from sray.platform.stability.point_spec import PointSpec
from sray.platform.stability.stress_scenes import StressScene, perturbed_views
from sray.platform.stability.view_choice import choose_sources, source_samples, unseen_fraction

AUTOCAST_DTYPES = {"bf16": torch.bfloat16, "fp16": torch.float16}
"""Inference precisions other than fp32, as autocast dtypes."""


def precision_context(precision: str, device: torch.device) -> contextlib.AbstractContextManager:
    """Autocast for ``precision`` (``fp32``: none); ValueError for fp16 off CUDA."""
    if precision == "fp32":
        return contextlib.nullcontext()
    if precision == "fp16" and device.type != "cuda":
        raise ValueError("precision fp16 needs a CUDA device (CPU autocast runs bf16)")
    return torch.autocast(device.type, dtype=AUTOCAST_DTYPES[precision])


def zero_shot_point(model: EvalModel, scenes: list[StressScene], spec: PointSpec, stride: int, chunk: int,
                    probe: tuple[int, float], poison: bool = False) -> dict[str, Any]:
    """Score ``model`` at ``spec`` on ``scenes``: mean dataset-level mIoU and PSNR, per-scene scores, the measured
    unseen fraction (``probe``: coarse depths per ray and the nearest depth a source sees, ``unseen_fraction``),
    non-finite rays and (below fp32) argmax agreement with the fp32 render.

    A perturbation touches the sources the spec picks for the scene's queries, drawn once per scene in view order.
    """
    watch = OutputWatch(poison)
    device = model.device
    per_scene, unseen, agree, total = {}, [], 0, 0
    for scene in scenes:
        views = scene.views
        if spec.perturbation is not None:
            ids = sorted({s for q in scene.test_ids for s in choose_sources(scene, q, spec)})
            views = perturbed_views(scene, ids, *spec.perturbation, spec.seed)
        samples = source_samples(scene, views, spec)
        with precision_context(spec.precision, device):
            scored = score_scene(lambda s: watch.wrap(model.renderer(s)), samples, model.n_classes, model.ignore_id,
                                 stride, chunk, device, model.fast)
        for sample, view in zip(samples, scored.views):
            if spec.precision != "fp32":
                fp32 = predict_view(model.renderer(sample), sample, stride, chunk, device, model.fast)
                agree += int((fp32.pred_label == view.pred_label).sum())
                total += fp32.pred_label.numel()
            unseen.append(unseen_fraction(sample, stride, *probe))
        per_scene[scene.name] = {"miou": scored.scores["miou"], "psnr": scored.scores["psnr"]}
    return {"miou": sum(s["miou"] for s in per_scene.values()) / len(per_scene),
            "psnr": sum(s["psnr"] for s in per_scene.values()) / len(per_scene),
            "unseen_fraction": sum(unseen) / len(unseen), "nonfinite_rays": watch.nonfinite_rays,
            "fp32_agreement": agree / total if total else None, "scenes": per_scene}
