"""Render held-out query views of one scene and score them (validation, ``sray eval``, the fleet).

Every score names its protocol (``sray.model.metrics``): semantic scores both from one confusion
matrix per scene ("dataset-level") and per image ("per-image mean"); colour by PSNR, and by SSIM
on whole images only (a strided render has no SSIM: its pixels are not neighbours in the image).
LPIPS is not reported: its backbones are downloaded at run time, which this platform cannot do.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor, nn

from sray.model.metrics import confusion_matrix, per_image_miou, psnr, scene_metrics
from sray.model.rays import pixel_rays
from sray.model.ssim import SSIM_WINDOW, ssim


@dataclass
class ViewPrediction:
    """One rendered query view (on a strided pixel grid) next to its ground truth."""

    query_id: str
    pred_label: Tensor
    """int64 (h, w) argmax of the fine pass's rendered logits."""
    pred_rgb: Tensor
    """float32 (h, w, 3) fine-pass colour in [0, 1]."""
    gt_label: Tensor
    """int64 (h, w) ground truth (ignore id = unlabelled)."""
    gt_rgb: Tensor
    """float32 (h, w, 3) ground-truth colour."""
    stride: int
    """Every ``stride``-th pixel of the query image in each direction; 1 = the whole image."""


def strided_pixels(h: int, w: int, stride: int) -> tuple[Tensor, int, int]:
    """Pixel centres (u, v) of every ``stride``-th pixel: exact pixels of the full image, so labels
    and colours are read without resampling. Returns (uv (h'*w', 2), h', w')."""
    vs = torch.arange(stride // 2, h, stride, dtype=torch.float32)
    us = torch.arange(stride // 2, w, stride, dtype=torch.float32)
    v, u = torch.meshgrid(vs, us, indexing="ij")
    return torch.stack([u.reshape(-1), v.reshape(-1)], dim=-1), len(vs), len(us)


@torch.no_grad()
def render_view(render: Any, sample: dict[str, Any], stride: int, chunk: int,
                device: torch.device) -> ViewPrediction:
    """Render one evaluation sample with ``render(origins, dirs, near, far) -> out`` in ray chunks.

    ``sample`` follows the evaluation-sample contract (docs/CONTRACTS.md): whole query image,
    fixed source views.
    """
    gt_rgb, gt_label = sample["query_rgb"], sample["query_label"]
    h, w = gt_label.shape
    uv, hh, ww = strided_pixels(h, w, stride)
    origins, dirs = pixel_rays(sample["query_K"].to(device), sample["query_c2w"].to(device), uv.to(device))
    labels, colours = [], []
    for start in range(0, uv.shape[0], chunk):
        sl = slice(start, start + chunk)
        n = origins[sl].shape[0]
        near = torch.full((n,), float(sample["near"]), device=device)
        far = torch.full((n,), float(sample["far"]), device=device)
        fine = render(origins[sl], dirs[sl], near, far)["fine"]
        labels.append(fine["logits"].float().argmax(-1).cpu())
        colours.append(fine["rgb"].float().clamp(0, 1).cpu())
    iu, iv = uv[:, 0].long(), uv[:, 1].long()
    return ViewPrediction(
        query_id=str(sample["query_id"]),
        pred_label=torch.cat(labels).reshape(hh, ww), pred_rgb=torch.cat(colours).reshape(hh, ww, 3),
        gt_label=gt_label[iv, iu].reshape(hh, ww).long(), gt_rgb=gt_rgb[iv, iu].reshape(hh, ww, 3).float(),
        stride=stride)


def sray_renderer(net: nn.Module, sample: dict[str, Any], device: torch.device) -> Any:
    """Encode the sample's fixed source views once; return a ray renderer bound to them."""
    src = net.encode(sample["src_rgb"].to(device), sample["src_K"].to(device), sample["src_c2w"].to(device))
    return lambda o, d, near, far: net.render_rays(src, o, d, near, far, stratified=False)


def score_views(views: list[ViewPrediction], n_classes: int, ignore_id: int) -> dict[str, float]:
    """Scene scores: dataset-level and per-image semantic metrics, PSNR and SSIM (mean over views).

    Keys: ``miou``, ``total_acc``, ``class_avg_acc`` (dataset-level protocol), ``miou_per_image``
    (per-image protocol), ``psnr``, and ``ssim`` only when every view is a whole image (stride 1):
    a strided render never gets an SSIM. Whole images smaller than the SSIM window score NaN.
    """
    conf = sum(confusion_matrix(v.pred_label, v.gt_label, n_classes, ignore_id) for v in views)
    dataset = scene_metrics(conf)
    per_image = per_image_miou([v.pred_label for v in views], [v.gt_label for v in views], n_classes, ignore_id)
    psnrs = [psnr(v.pred_rgb, v.gt_rgb) for v in views]
    scores = {"miou": float(dataset["miou"]), "total_acc": float(dataset["total_acc"]),
              "class_avg_acc": float(dataset["class_avg_acc"]), "miou_per_image": float(per_image["miou"]),
              "psnr": sum(psnrs) / len(psnrs)}
    if all(v.stride == 1 for v in views):
        big = all(min(v.gt_label.shape) >= SSIM_WINDOW for v in views)
        ssims = [ssim(v.pred_rgb, v.gt_rgb) for v in views] if big else [float("nan")]
        scores["ssim"] = sum(ssims) / len(ssims)
    return scores
