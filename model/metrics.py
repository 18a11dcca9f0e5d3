"""Segmentation and image-quality metrics, each result naming its protocol.

Segmentation (rows of a confusion matrix = ground truth, columns = prediction; pixels whose
ground truth is the ignore id are left out, so the ignore id is never a target):

- ``scene_metrics``: ONE confusion matrix per scene, accumulated over all its test images;
  mIoU, total accuracy and class-average accuracy over the classes present in that scene's
  ground truth (Semantic-NeRF's dataset-level protocol).
- ``per_image_miou``: the same numbers per image, over the classes present in that image's
  ground truth, then averaged over images (the protocol of the S-Ray authors' code).

For a class ``c`` present in the ground truth, ``IoU_c = TP / (TP + FP + FN)``. A class that is
predicted but absent from the ground truth is not a class of the mean; its pixels are false
negatives of the true classes they cover, so they lower those classes' IoU and accuracy.

Colour: ``psnr`` and ``ssim`` (re-exported from ``sray.model.ssim``) for images in [0, 1].
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from sray.model.ssim import SSIM_PROTOCOL, ssim

__all__ = [
    "DATASET_PROTOCOL",
    "LPIPS_NOTE",
    "PER_IMAGE_PROTOCOL",
    "SSIM_PROTOCOL",
    "confusion_matrix",
    "per_image_miou",
    "psnr",
    "scene_metrics",
    "ssim",
]

DATASET_PROTOCOL = "dataset-level, classes present in ground truth"
PER_IMAGE_PROTOCOL = "per-image mean"
LPIPS_NOTE = (
    "LPIPS not reported: every available implementation downloads its pretrained backbone "
    "(AlexNet/VGG) at run time, and the machines that produced these numbers are offline."
)


def confusion_matrix(pred: Tensor, target: Tensor, n_classes: int, ignore_id: int) -> Tensor:
    """Counts (L, L) int64 of (ground truth row, predicted column) over non-ignored pixels.

    pred, target: integer tensors of the same shape (any). Predictions must lie in [0, L);
    targets in [0, L) or equal ``ignore_id``.
    """
    if pred.shape != target.shape:
        raise ValueError(
            "sray.model.metrics.confusion_matrix: `pred` and `target` must have the same shape, "
            f"got {tuple(pred.shape)} and {tuple(target.shape)}."
        )
    if pred.is_floating_point() or target.is_floating_point():
        raise ValueError(
            "sray.model.metrics.confusion_matrix: `pred` and `target` must be integer class ids; "
            "take `logits.argmax(-1)` first."
        )
    keep = target.reshape(-1) != ignore_id
    p = pred.reshape(-1)[keep].long()
    t = target.reshape(-1)[keep].long()
    for name, v in (("pred", p), ("target", t)):
        if v.numel() and (int(v.min()) < 0 or int(v.max()) >= n_classes):
            raise ValueError(
                f"sray.model.metrics.confusion_matrix: `{name}` holds ids outside [0, {n_classes})"
                f" (range {int(v.min())}..{int(v.max())}, ignore id {ignore_id}); check the label "
                "space against n_classes."
            )
    flat = torch.bincount(t * n_classes + p, minlength=n_classes * n_classes)
    return flat.reshape(n_classes, n_classes).to(torch.int64)


def _confusion_scores(conf: Tensor) -> dict[str, float | list[float] | int]:
    """mIoU, total and class-average accuracy over the GT-present classes of one matrix."""
    conf = conf.to(torch.float64)
    tp = conf.diagonal()
    gt_count = conf.sum(1)  # (L,) pixels of each ground-truth class
    pred_count = conf.sum(0)  # (L,) pixels predicted as each class
    present = gt_count > 0
    nan = torch.full_like(tp, float("nan"))
    iou = torch.where(present, tp / (gt_count + pred_count - tp).clamp_min(1), nan)
    acc = torch.where(present, tp / gt_count.clamp_min(1), nan)
    n_present = int(present.sum())
    total = float(conf.sum())
    return {
        "miou": float(iou[present].mean()) if n_present else float("nan"),
        "total_acc": float(tp.sum() / total) if total else float("nan"),
        "class_avg_acc": float(acc[present].mean()) if n_present else float("nan"),
        "iou_per_class": iou.tolist(),
        "n_classes_present": n_present,
    }


def scene_metrics(conf: Tensor) -> dict[str, float | list[float] | int | str]:
    """Dataset-level metrics of one scene from its accumulated (L, L) confusion matrix.

    Returns ``miou``, ``total_acc``, ``class_avg_acc`` (NaN when nothing is labelled),
    ``iou_per_class`` (NaN for classes absent from the ground truth), ``n_classes_present``,
    ``n_pixels`` and ``protocol``.
    """
    if conf.ndim != 2 or conf.shape[0] != conf.shape[1]:
        raise ValueError(
            f"sray.model.metrics.scene_metrics: expected a square (L, L) confusion matrix, got "
            f"{tuple(conf.shape)}."
        )
    scores: dict[str, float | list[float] | int | str] = dict(_confusion_scores(conf))
    scores["n_pixels"] = int(conf.sum())
    scores["protocol"] = DATASET_PROTOCOL
    return scores


def per_image_miou(
    preds: Sequence[Tensor] | Tensor, targets: Sequence[Tensor] | Tensor, n_classes: int,
    ignore_id: int,
) -> dict[str, float | int | str]:
    """Per-image mIoU (and total / class-average accuracy), averaged over images.

    preds, targets: sequences (or stacked tensors, first dim = image) of (H, W) integer maps.
    Each image's scores use the classes present in that image's ground truth; an image without
    any labelled pixel is skipped and counted in ``n_images_skipped``.
    """
    if len(preds) != len(targets):
        raise ValueError(
            f"sray.model.metrics.per_image_miou: got {len(preds)} predictions for "
            f"{len(targets)} ground-truth images."
        )
    mious: list[float] = []
    totals: list[float] = []
    class_accs: list[float] = []
    for pred, target in zip(preds, targets, strict=True):
        conf = confusion_matrix(pred, target, n_classes, ignore_id)
        if int(conf.sum()) == 0:
            continue
        s = _confusion_scores(conf)
        mious.append(float(s["miou"]))
        totals.append(float(s["total_acc"]))
        class_accs.append(float(s["class_avg_acc"]))
    n = len(mious)
    return {
        "miou": sum(mious) / n if n else float("nan"),
        "total_acc": sum(totals) / n if n else float("nan"),
        "class_avg_acc": sum(class_accs) / n if n else float("nan"),
        "n_images": n,
        "n_images_skipped": len(preds) - n,
        "protocol": PER_IMAGE_PROTOCOL,
    }


def psnr(pred: Tensor, target: Tensor) -> float:
    """PSNR in dB of images in [0, 1] (any equal shapes): -10 log10(MSE); inf if identical."""
    if pred.shape != target.shape:
        raise ValueError(
            f"sray.model.metrics.psnr: shapes differ: {tuple(pred.shape)} vs "
            f"{tuple(target.shape)}."
        )
    mse = torch.mean((pred.double() - target.double()) ** 2)
    return float(-10.0 * torch.log10(mse))
