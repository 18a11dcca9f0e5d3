"""One point of the suite for a zero-shot row (the method's ``eval_model``, rendered and scored as ``sray eval``
does: at the clean point the same scores), and the watch over every point's renders.
"""

from __future__ import annotations

import contextlib
from typing import Any

import torch
from torch import Tensor

from sray.model.view_render import RayRenderer
from sray.platform.eval.eval_model import EvalModel
from sray.platform.eval.view_scoring import predict_view, score_scene
from sray.platform.stability.axes import PointSpec
from sray.platform.stability.stress_scenes import (StressScene, choose_sources, perturbed_views, source_samples,
                                                   unseen_fraction)

AUTOCAST_DTYPES = {"bf16": torch.bfloat16, "fp16": torch.float16}
"""Inference precisions other than fp32, as autocast dtypes."""


class OutputWatch:
    """Wraps renderers: counts rays whose fine outputs are not finite (a point with any is ``failed``), and can
    poison them with NaN (the fault drill ``stability.nan_points``). A ray with every logit -inf (``2d-transfer``
    where no source sees the pixel) is a miss, not a non-finite output: only NaN and +inf count."""

    def __init__(self, poison: bool) -> None:
        """``poison``: replace every rendered logit with NaN."""
        self.nonfinite_rays, self.poison = 0, poison

    def wrap(self, render: RayRenderer) -> RayRenderer:
        """The renderer, watched."""

        def watched(o: Tensor, d: Tensor, near: Tensor, far: Tensor) -> dict[str, dict[str, Tensor]]:
            out = render(o, d, near, far)
            fine = out["fine"]
            if self.poison:
                fine = {**fine, "logits": torch.full_like(fine["logits"], float("nan"))}
                out = {**out, "fine": fine}
            logits, rgb = fine["logits"], fine["rgb"]                                       # (R, L), (R, 3)
            bad = (torch.isnan(logits) | torch.isposinf(logits)).any(-1) | ~torch.isfinite(rgb).all(-1)  # (R,)
            self.nonfinite_rays += int(bad.sum())
            return out

        return watched


def precision_context(precision: str, device: torch.device) -> contextlib.AbstractContextManager:
    """Autocast for ``precision`` (``fp32``: none); ValueError for fp16 off CUDA."""
    if precision == "fp32":
        return contextlib.nullcontext()
    if precision == "fp16" and device.type != "cuda":
        raise ValueError("precision fp16 needs a CUDA device (CPU autocast runs bf16)")
    return torch.autocast(device.type, dtype=AUTOCAST_DTYPES[precision])


def zero_shot_point(model: EvalModel, scenes: list[StressScene], spec: PointSpec, stride: int, chunk: int,
                    probe: tuple[int, float], poison: bool = False) -> dict[str, Any]:
    """Score ``model`` at ``spec`` on ``scenes``: mean mIoU and PSNR, per-scene scores, the unseen fraction
    (``probe``: coarse depths per ray, nearest source depth), non-finite rays and (below fp32) argmax agreement with
    the fp32 render. A perturbation touches the sources the spec picks, drawn once per scene in view order."""
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
