"""Every held-out score's render-and-score loop (:func:`score_scene`): semantics by one confusion matrix per scene
("dataset-level") and per image, a pixel without prediction (all logits -inf) a miss; colour by PSNR, and SSIM on
whole images only. No LPIPS: its backbones are downloaded at run time."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from sray.data_tools.loader.sample_types import EvalSample
from sray.model.fast_render import FastRender
from sray.model.metrics import confusion_matrix, per_image_miou, psnr, scene_metrics
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SourceSet
from sray.model.ssim import SSIM_WINDOW, ssim
from sray.model.view_render import RayRenderer, render_view, strided_pixels
from sray.platform.eval.label_transfer import UNSEEN, unseen_as_class


@dataclass
class ViewPrediction:
    """One rendered query view (on a strided pixel grid) next to its ground truth."""

    query_id: str
    pred_label: Tensor
    """int64 (h, w) argmax of the fine pass's rendered logits; ``UNSEEN`` where they are all -inf (no prediction)."""
    pred_rgb: Tensor
    """float32 (h, w, 3) fine-pass colour in [0, 1]."""
    gt_label: Tensor
    """int64 (h, w) ground truth (ignore id = unlabelled)."""
    gt_rgb: Tensor
    """float32 (h, w, 3) ground-truth colour."""
    stride: int
    """Every ``stride``-th pixel of the query image in each direction; 1 = the whole image."""


@torch.no_grad()
def predict_view(render: RayRenderer, sample: EvalSample, stride: int, chunk: int, device: torch.device,
                 fast: FastRender | None = None) -> ViewPrediction:
    """Render one evaluation sample with ``render`` (bound to its sources) in ``chunk``-ray chunks (0: by device) at
    every ``stride``-th pixel (``render_view``; the fast mode's with ``fast``, which ``render`` must match)."""
    gt_rgb, gt_label = sample.query_rgb, sample.query_label
    h, w = gt_label.shape
    fine = render_view(render, sample.query.K, sample.query.c2w, (h, w), sample.near, sample.far, chunk, device,
                       stride, fast, passes=("fine",), keys=("logits", "rgb"))["fine"]
    uv, hh, ww = strided_pixels(h, w, stride)
    iu, iv = uv[:, 0].long(), uv[:, 1].long()
    logits = fine["logits"]  # (h', w', L)
    pred = torch.where(torch.isneginf(logits).all(-1), UNSEEN, logits.argmax(-1))  # (h', w')
    return ViewPrediction(
        query_id=sample.query_id, pred_label=pred.cpu(), pred_rgb=fine["rgb"].cpu(),
        gt_label=gt_label[iv, iu].reshape(hh, ww).long(), gt_rgb=gt_rgb[iv, iu].reshape(hh, ww, 3).float(),
        stride=stride)


def encode_sources(net: nn.Module, sample: EvalSample, device: torch.device) -> SourceSet:
    """The sample's fixed source views, moved to ``device`` and encoded by the S-Ray ``net``."""
    sources = sample.sources.to(device)
    return net.encode(sources.rgb, sources.K, sources.c2w, sources.depth)


def sray_renderer(net: nn.Module, sample: EvalSample, device: torch.device, fast: FastRender | None = None,
                  runtime: Runtime = Runtime()) -> RayRenderer:
    """The S-Ray ray renderer bound to the sample's encoded sources (the fast mode's with ``fast``), run by runtime."""
    return net.ray_renderer(encode_sources(net, sample, device), fast, runtime)


def scene_confusion(views: list[ViewPrediction], n_classes: int, ignore_id: int) -> Tensor:
    """One (L+1, L+1) int64 confusion matrix over ``views``; column L counts pixels without prediction, row L is 0."""
    return sum(confusion_matrix(unseen_as_class(v.pred_label, n_classes), v.gt_label, n_classes + 1, ignore_id)
               for v in views)


def per_image_scores(views: list[ViewPrediction], n_classes: int, ignore_id: int) -> dict[str, float]:
    """``per_image_miou`` of ``views``, pixels without prediction counted as misses (``unseen_as_class``)."""
    return per_image_miou([unseen_as_class(v.pred_label, n_classes) for v in views], [v.gt_label for v in views],
                          n_classes + 1, ignore_id)


def class_ious(views: list[ViewPrediction], n_classes: int, ignore_id: int) -> list[float | None]:
    """Dataset-level IoU of each of the L classes over ``views``, None for a class absent from their ground truth."""
    ious = scene_metrics(scene_confusion(views, n_classes, ignore_id))["iou_per_class"][:n_classes]
    return [None if math.isnan(v) else float(v) for v in ious]


def score_views(views: list[ViewPrediction], n_classes: int, ignore_id: int) -> dict[str, float]:
    """Scene scores: ``miou``, ``total_acc``, ``class_avg_acc`` (dataset-level), ``miou_per_image``, ``psnr`` and,
    only when every view is a whole image, ``ssim`` (NaN for images smaller than its window); means over views."""
    dataset = scene_metrics(scene_confusion(views, n_classes, ignore_id))
    per_image = per_image_scores(views, n_classes, ignore_id)
    psnrs = [psnr(v.pred_rgb, v.gt_rgb) for v in views]
    scores = {"miou": float(dataset["miou"]), "total_acc": float(dataset["total_acc"]),
              "class_avg_acc": float(dataset["class_avg_acc"]), "miou_per_image": float(per_image["miou"]),
              "psnr": sum(psnrs) / len(psnrs)}
    if all(v.stride == 1 for v in views):
        big = all(min(v.gt_label.shape) >= SSIM_WINDOW for v in views)
        ssims = [ssim(v.pred_rgb, v.gt_rgb) for v in views] if big else [float("nan")]
        scores["ssim"] = sum(ssims) / len(ssims)
    return scores


@dataclass(frozen=True)
class ScoredScene:
    """A scene's rendered held-out views and their scores."""

    scores: dict[str, float]
    views: list[ViewPrediction]


def score_scene(renderer: Callable[[EvalSample], RayRenderer], samples: Iterable[EvalSample], n_classes: int,
                ignore_id: int, stride: int, chunk: int, device: torch.device, fast: FastRender | None = None,
                on_view: Callable[[ViewPrediction], None] | None = None) -> ScoredScene:
    """Render every sample of one scene with ``renderer(sample)`` (as ``predict_view``, under the caller's autocast),
    then score them in float32; ``on_view`` gets each view once rendered. ValueError when there is no sample."""
    views = []
    for sample in samples:
        views.append(predict_view(renderer(sample), sample, stride, chunk, device, fast))
        if on_view is not None:
            on_view(views[-1])
    if not views:
        raise ValueError("sray.platform.eval.view_scoring: no evaluation sample to score; the scene needs at "
                         "least one held-out (test) view")
    with torch.autocast("cpu", enabled=False):
        return ScoredScene(score_views(views, n_classes, ignore_id), views)
