"""``SRayModel``: the Semantic Ray network (S-Ray, CVPR 2023) with coarse-to-fine volume rendering.

Usage (pixelNeRF's encode / query split; the module keeps no state between the calls)::

    src = model.encode(src_rgb, src_K, src_c2w)          # once per source set
    out = model.render_rays(src, origins, dirs, near, far, stratified=True)   # any number of times

Design choices where the paper is silent:

* One shared ResUNet encoder; two separate per-sample networks (``coarse`` for n_coarse samples,
  ``fine`` for the sorted union of coarse and fine samples), as the paper's public code does.
* Coarse samples: equal bins between the scene's near and far, stratified in training and bin
  centres in evaluation. Fine samples: inverse CDF of the detached coarse weights
  (``rendering.sample_pdf``), with the same stratified / deterministic switch.
* The semantic logits of every sample are composited with the density weights (the paper's
  semantic field rendering); colour comes from the geometry net's blending head.
* Sampling, compositing and the whole-image loop are ``sray.model.hierarchical``'s, shared with
  Semantic-NeRF; this class supplies the per-pass field.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from .config import SRayConfig
from .encoder import ResUNetEncoder
from .fast_render import render_rays_fast
from .field import SRayField
from .hierarchical import render_image, render_rays
from .source_set import SourceSet, rigid_inverse

__all__ = ["SRayModel", "SourceSet"]


class SRayModel(nn.Module):
    """The S-Ray network: encoder, coarse and fine fields, volume rendering of semantics and colour."""

    def __init__(self, cfg: SRayConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.encoder = ResUNetEncoder(cfg.feat_dim)
        self.coarse = SRayField(cfg)
        self.fine = SRayField(cfg)

    def encode(self, src_rgb: Tensor, src_K: Tensor, src_c2w: Tensor) -> SourceSet:
        """Encode m source views once: src_rgb (m, 3, H, W) in [0, 1], src_K (m, 3, 3), src_c2w (m, 4, 4)."""
        m = src_rgb.shape[0]
        if src_rgb.ndim != 4 or src_K.shape != (m, 3, 3) or src_c2w.shape != (m, 4, 4):
            raise ValueError(
                "sray.model.semantic_ray.encode: expected src_rgb (m, 3, H, W), src_K (m, 3, 3), src_c2w "
                f"(m, 4, 4); got {tuple(src_rgb.shape)}, {tuple(src_K.shape)}, {tuple(src_c2w.shape)}."
            )
        if not src_rgb.is_floating_point():
            raise ValueError(f"sray.model.semantic_ray.encode: src_rgb must be float in [0, 1], got {src_rgb.dtype}; "
                             "divide uint8 images by 255.")
        feats = self.encoder(src_rgb)  # (m, C, H/4, W/4)
        c2w = src_c2w.float()
        return SourceSet(feats=feats, rgb=src_rgb, K=src_K.float(), c2w=c2w, w2c=rigid_inverse(c2w))

    def render_rays(self, src: SourceSet, origins: Tensor, dirs: Tensor, near: Tensor | float,
                    far: Tensor | float, stratified: bool,
                    generator: torch.Generator | None = None) -> dict[str, dict[str, Tensor]]:
        """Render rays o + t d, t in [near, far] (camera z-depth for ``pixel_rays`` directions).

        origins, dirs: (R, 3); near, far: scalars or (R,). ``stratified`` jitters coarse and fine
        samples (training); otherwise sampling is deterministic (evaluation).
        Returns ``{"coarse": pass, "fine": pass}`` (see ``hierarchical.render_rays``).
        """
        fields = {"coarse": self.coarse, "fine": self.fine}

        def field(name: str, o: Tensor, d: Tensor, z: Tensor, lo: Tensor, hi: Tensor) -> dict[str, Tensor]:
            return fields[name](src, o, d, z, lo, hi)

        return render_rays(field, origins, dirs, near, far, self.cfg.n_coarse, self.cfg.n_fine, stratified,
                           generator, self.cfg.fine_samples)

    @torch.no_grad()
    def render_rays_fast(self, src: SourceSet, origins: Tensor, dirs: Tensor, near: Tensor | float,
                         far: Tensor | float, confidence: float) -> dict[str, dict[str, Tensor]]:
        """The fast render mode's rays (``fast_render.render_rays_fast``): deterministic, no grad; a
        fine pass only for rays whose coarse confidence is below ``confidence``."""
        fields = {"coarse": self.coarse, "fine": self.fine}

        def field(name: str, o: Tensor, d: Tensor, z: Tensor, lo: Tensor, hi: Tensor) -> dict[str, Tensor]:
            return fields[name](src, o, d, z, lo, hi)

        return render_rays_fast(field, origins, dirs, near, far, self.cfg.n_coarse, self.cfg.n_fine, confidence)

    @torch.no_grad()
    def render_image(self, src: SourceSet, K: Tensor, c2w: Tensor, hw: tuple[int, int],
                     near: Tensor | float, far: Tensor | float,
                     chunk: int | None = None) -> dict[str, dict[str, Tensor]]:
        """Render a whole (H, W) query image in chunks of rays, deterministic sampling, no grad.

        K (3, 3), c2w (4, 4) of the query camera; near, far scalars. Returns ``{"coarse": ...,
        "fine": ...}`` with ``logits`` (H, W, L), ``rgb`` (H, W, 3), ``depth`` (H, W) and
        ``opacity`` (H, W) per pass. Memory is bounded by ``chunk`` rays (default ``cfg.chunk``).
        """
        return render_image(lambda o, d: self.render_rays(src, o, d, near, far, stratified=False),
                            K, c2w, hw, int(chunk or self.cfg.chunk), src.feats.device)
