"""The model surface: ``RayBatch`` (m source views and :class:`QueryRays` of one scene: query camera, pixels, the
scene's z-depth bounds as floats) and the module that renders it. :meth:`QueryRays.rays` is the one place pixels
become rays and bounds per-ray tensors (``torch.full`` on the device: no host-to-device copy).
``RayBatchLoss.forward`` encodes the sources and computes the training loss: DDP synchronises gradients only for
work inside ``forward`` (checkpoints store ``net``'s own keys)."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from .config import SRayConfig
from .rays import pixel_rays
from .runtime import Runtime
from .semantic_ray import SRayModel
from .source_semantics import source_semantic_loss


@dataclass(frozen=True)
class QueryRays:
    """Rays through pixels of one query camera, with the scene's depth bounds."""

    K: Tensor
    """float32 (3, 3) query intrinsics (pixel (u, v) centred at (u, v))."""
    c2w: Tensor
    """float32 (4, 4) query camera-to-world, OpenCV axes."""
    pixels: Tensor
    """float32 (R, 2) (u, v) pixel coordinates of the rays."""
    near: float
    """Near z-depth bound (metres) of every ray."""
    far: float
    """Far z-depth bound (metres) of every ray."""

    def to(self, device: torch.device | str, non_blocking: bool = False) -> QueryRays:
        """A copy with the camera and pixels on ``device``."""
        return QueryRays(self.K.to(device, non_blocking=non_blocking), self.c2w.to(device, non_blocking=non_blocking),
                         self.pixels.to(device, non_blocking=non_blocking), self.near, self.far)

    def rays(self) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """origins, dirs (R, 3) (``pixel_rays``: t is the z-depth) and near, far (R,) float32 on the pixels' device."""
        origins, dirs = pixel_rays(self.K, self.c2w, self.pixels)
        n, device = self.pixels.shape[0], self.pixels.device
        near = torch.full((n,), self.near, dtype=torch.float32, device=device)  # (R,)
        far = torch.full((n,), self.far, dtype=torch.float32, device=device)  # (R,)
        return origins, dirs, near, far


@dataclass(frozen=True)
class RayBatch:
    """The model's input: the source views of one scene and query rays to render against them."""

    src_rgb: Tensor
    """float32 (m, 3, H, W) source colours in [0, 1]."""
    src_K: Tensor
    """float32 (m, 3, 3) source intrinsics."""
    src_c2w: Tensor
    """float32 (m, 4, 4) source camera-to-world, OpenCV axes."""
    query: QueryRays
    """The rays to render."""
    src_depth: Tensor | None = None
    """float32 (m, H, W) source z-depth in metres, 0 = unknown (read only with ``model.inputs='rgbd'``)."""
    src_label: Tensor | None = None
    """int64 (m, H, W) source class ids (ignore id: unlabelled), read only by the source-view loss term."""


class RayBatchLoss(nn.Module):
    """What training runs (DDP included): one ``forward`` encodes a :class:`RayBatch`'s sources and computes
    ``SRayModel.training_loss`` of its rays plus ``lambda_src_sem`` times the source views' cross-entropy
    (``source_semantics``) when on and the batch has source labels; ``runtime``: how the loss of ``net`` is run."""

    def __init__(self, cfg: SRayConfig, runtime: Runtime = Runtime()) -> None:
        """Build the S-Ray network it trains (no device work here); ``runtime``: how its loss is run."""
        super().__init__()
        self.net = SRayModel(cfg)
        self.runtime = runtime

    def forward(self, batch: RayBatch, target_label: Tensor, target_rgb: Tensor,
                render: bool = True) -> tuple[Tensor, dict[str, Tensor]]:
        """(scalar loss, detached terms: ``render_loss``'s and ``sem_src``, the source-view term) for the batch's R
        rays: target_label (R,) int64 (ignore id: unlabelled), target_rgb (R, 3) in [0, 1]. ``render=False`` (2D
        warm-up): the source-view term alone, every other parameter in the loss with weight 0 (DDP needs a gradient
        for each parameter every step)."""
        net = self.net
        src = net.encode(batch.src_rgb, batch.src_K, batch.src_c2w, batch.src_depth)
        use_src = net.src_head is not None and batch.src_label is not None
        if not render and not use_src:
            raise ValueError("sray.model.ray_batch: a 2D-only step needs model.lambda_src_sem > 0 and source "
                             "labels in the batch (src_label); set model.lambda_src_sem or render the rays.")
        if render:
            loss, terms = net.training_loss(src, *batch.query.rays(), target_label, target_rgb, self.runtime)
        else:
            idle = [p for name, p in net.named_parameters() if not name.startswith(("encoder.", "src_head."))]
            loss = torch.stack([p.view(-1)[0] for p in idle]).sum() * 0.0
            terms = {}
        if use_src:
            logits = net.src_head(src.feats, tuple(batch.src_rgb.shape[-2:]))  # (m, L, H, W)
            src_loss = source_semantic_loss(logits, batch.src_label, net.cfg)
            loss = loss + net.cfg.lambda_src_sem * src_loss
            terms = terms | {"sem_src": src_loss.detach()}
        return loss, terms
