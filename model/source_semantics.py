"""Dense 2D supervision of the encoder (a departure from the paper, docs/model.md, "Dense 2D supervision of the
encoder"): a 1x1-conv semantic head on the source views' feature maps, up-sampled to full resolution with the
encoder's centre-aligned rule, and its cross-entropy against their own labels; used in training only."""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from .config import SRayConfig
from .encoder import FEATURE_STRIDE, upsample_to
from .losses import labelled_cross_entropy


class SourceSemanticHead(nn.Module):
    """Linear per-pixel classifier on encoder features: (m, C, h, w) -> logits (m, L, H, W)."""

    def __init__(self, cfg: SRayConfig) -> None:
        """A 1x1 convolution from ``cfg.feat_dim`` channels to ``cfg.n_classes`` logits (no device work)."""
        super().__init__()
        self.classify = nn.Conv2d(cfg.feat_dim, cfg.n_classes, 1)

    def forward(self, feats: Tensor, image_hw: tuple[int, int]) -> Tensor:
        """Logits (m, L, H, W) at the images' size ``image_hw`` from the encoder's features (m, C, h, w)."""
        h, w = image_hw
        expected = (math.ceil(math.ceil(h / 2) / 2), math.ceil(math.ceil(w / 2) / 2))
        if tuple(feats.shape[-2:]) != expected:
            raise ValueError(f"sray.model.source_semantics: features {tuple(feats.shape[-2:])} do not belong to "
                             f"{image_hw} images (expected {expected} at stride {FEATURE_STRIDE}); pass the encoder's "
                             "output for these source images.")
        logits = self.classify(feats)  # (m, L, h, w)
        half = upsample_to(logits, (math.ceil(h / 2), math.ceil(w / 2)))  # (m, L, H/2, W/2)
        return upsample_to(half, (h, w))  # (m, L, H, W)


def source_semantic_loss(logits: Tensor, labels: Tensor, cfg: SRayConfig) -> Tensor:
    """Mean (class-weighted) float32 cross-entropy of source-view logits (m, L, H, W) against labels (m, H, W) int64
    (``cfg.ignore_id``: unlabelled, left out), whatever the autocast; 0 with a zero gradient when none is labelled."""
    if labels.shape != (logits.shape[0], *logits.shape[-2:]) or labels.dtype != torch.int64:
        raise ValueError(f"sray.model.source_semantics: labels must be int64 (m, H, W) = "
                         f"{(logits.shape[0], *logits.shape[-2:])} for logits {tuple(logits.shape)}, got "
                         f"{labels.dtype} {tuple(labels.shape)}; pass the source views' label maps at their size.")
    flat_logits = logits.permute(0, 2, 3, 1).reshape(-1, logits.shape[1])  # (m H W, L)
    weight = torch.tensor(cfg.class_weights, dtype=torch.float32, device=logits.device) if cfg.class_weights else None
    with torch.autocast(device_type=logits.device.type, enabled=False):
        return labelled_cross_entropy(flat_logits.float(), labels.reshape(-1), cfg.ignore_id, weight)
