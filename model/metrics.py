"""Segmentation and image-quality metrics, each result naming its protocol. Confusion matrices: ground truth in
rows, predictions in columns, ignore-id pixels left out. ``scene_metrics``: one matrix per scene, scores over the
classes present in its ground truth (Semantic-NeRF's dataset-level protocol); ``per_image_miou``: the same per image,
averaged (the S-Ray authors' code). A class predicted but absent from the ground truth is not in the mean; its
pixels are false negatives of the classes they cover."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

DATASET_PROTOCOL = "dataset-level, classes present in ground truth"
PER_IMAGE_PROTOCOL = "per-image mean"
LPIPS_NOTE = ("LPIPS not reported: every available implementation downloads its pretrained backbone (AlexNet/VGG) at "
              "run time, and the machines that produced these numbers are offline.")


def confusion_matrix(pred: Tensor, target: Tensor, n_classes: int, ignore_id: int) -> Tensor:
    """Counts (L, L) int64 of (ground truth, prediction) over the non-ignored pixels of integer maps."""
    if pred.shape != target.shape:
        raise ValueError("sray.model.metrics.confusion_matrix: `pred` and `target` must have the same shape, "
                         f"got {tuple(pred.shape)} and {tuple(target.shape)}.")
    if pred.is_floating_point() or target.is_floating_point():
        raise ValueError("sray.model.metrics.confusion_matrix: `pred` and `target` must be integer class ids; "
                         "take `logits.argmax(-1)` first.")
    keep = target.reshape(-1) != ignore_id
    p = pred.reshape(-1)[keep].long()
    t = target.reshape(-1)[keep].long()
    for name, v in (("pred", p), ("target", t)):
        if v.numel() and (int(v.min()) < 0 or int(v.max()) >= n_classes):
            raise ValueError(f"sray.model.metrics.confusion_matrix: `{name}` holds ids outside [0, {n_classes}) (range "
                             f"{int(v.min())}..{int(v.max())}, ignore id {ignore_id}); check the label space against "
                             "n_classes.")
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
    return {"miou": float(iou[present].mean()) if n_present else float("nan"),
            "total_acc": float(tp.sum() / total) if total else float("nan"),
            "class_avg_acc": float(acc[present].mean()) if n_present else float("nan"),
            "iou_per_class": iou.tolist(), "n_classes_present": n_present}


def scene_metrics(conf: Tensor) -> dict[str, float | list[float] | int | str]:
    """Dataset-level metrics of one scene from its accumulated (L, L) confusion matrix: ``miou``, ``total_acc``,
    ``class_avg_acc`` (NaN when nothing is labelled), ``iou_per_class`` (NaN for classes absent from the ground
    truth), ``n_classes_present``, ``n_pixels`` and ``protocol``."""
    if conf.ndim != 2 or conf.shape[0] != conf.shape[1]:
        raise ValueError(f"sray.model.metrics.scene_metrics: expected a square (L, L) confusion matrix, got "
                         f"{tuple(conf.shape)}.")
    scores: dict[str, float | list[float] | int | str] = dict(_confusion_scores(conf))
    scores["n_pixels"] = int(conf.sum())
    scores["protocol"] = DATASET_PROTOCOL
    return scores


def per_image_miou(preds: Sequence[Tensor] | Tensor, targets: Sequence[Tensor] | Tensor, n_classes: int,
                   ignore_id: int) -> dict[str, float | int | str]:
    """Per-image mIoU, total and class-average accuracy (each over the classes present in that image's ground
    truth), averaged over the (H, W) integer maps of ``preds`` and ``targets`` (sequences or stacked); an image
    without a labelled pixel is skipped and counted in ``n_images_skipped``."""
    if len(preds) != len(targets):
        raise ValueError(f"sray.model.metrics.per_image_miou: got {len(preds)} predictions for {len(targets)} "
                         "ground-truth images.")
    confs = [confusion_matrix(p, t, n_classes, ignore_id) for p, t in zip(preds, targets, strict=True)]
    scores = [_confusion_scores(c) for c in confs if int(c.sum()) != 0]
    n = len(scores)
    keys = ("miou", "total_acc", "class_avg_acc")
    means = {k: sum(float(s[k]) for s in scores) / n if n else float("nan") for k in keys}
    return {**means, "n_images": n, "n_images_skipped": len(preds) - n, "protocol": PER_IMAGE_PROTOCOL}


def psnr(pred: Tensor, target: Tensor) -> float:
    """PSNR in dB of images in [0, 1] (any equal shapes): -10 log10(MSE); inf if identical."""
    if pred.shape != target.shape:
        raise ValueError(f"sray.model.metrics.psnr: shapes differ: {tuple(pred.shape)} vs {tuple(target.shape)}.")
    mse = torch.mean((pred.double() - target.double()) ** 2)
    return float(-10.0 * torch.log10(mse))
