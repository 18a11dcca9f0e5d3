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
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from .config import SRayConfig
from .encoder import ResUNetEncoder
from .field import SRayField
from .rays import image_pixels, pixel_rays
from .rendering import composite, merge_samples, sample_pdf, sample_uniform
from .source_set import SourceSet, rigid_inverse

__all__ = ["SRayModel", "SourceSet"]

IMAGE_KEYS = ("logits", "rgb", "depth", "opacity")
"""Per-pass outputs ``render_image`` assembles into images (weights and z are left out)."""


def _per_ray(value: Tensor | float, n_rays: int, like: Tensor) -> Tensor:
    """A scalar, 0-d or (R,) bound as an (R,) tensor on ``like``'s device, float32."""
    t = torch.as_tensor(value, dtype=torch.float32, device=like.device)
    if t.ndim == 0:
        return t.expand(n_rays)
    if t.shape != (n_rays,):
        raise ValueError(f"sray.model.sray: near/far must be scalars or ({n_rays},), got {tuple(t.shape)}.")
    return t


class SRayModel(nn.Module):
    """The S-Ray network: encoder, coarse and fine fields, volume rendering of semantics and colour."""

    def __init__(self, cfg: SRayConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.encoder = ResUNetEncoder(cfg.feat_dim)
        self.coarse = SRayField(cfg, cfg.n_coarse)
        self.fine = SRayField(cfg, cfg.n_fine_total)

    def encode(self, src_rgb: Tensor, src_K: Tensor, src_c2w: Tensor) -> SourceSet:
        """Encode m source views once: src_rgb (m, 3, H, W) in [0, 1], src_K (m, 3, 3), src_c2w (m, 4, 4)."""
        m = src_rgb.shape[0]
        if src_rgb.ndim != 4 or src_K.shape != (m, 3, 3) or src_c2w.shape != (m, 4, 4):
            raise ValueError(
                "sray.model.sray.encode: expected src_rgb (m, 3, H, W), src_K (m, 3, 3), src_c2w "
                f"(m, 4, 4); got {tuple(src_rgb.shape)}, {tuple(src_K.shape)}, {tuple(src_c2w.shape)}."
            )
        if not src_rgb.is_floating_point():
            raise ValueError(f"sray.model.sray.encode: src_rgb must be float in [0, 1], got {src_rgb.dtype}; "
                             "divide uint8 images by 255.")
        feats = self.encoder(src_rgb)  # (m, C, H/4, W/4)
        c2w = src_c2w.float()
        return SourceSet(feats=feats, rgb=src_rgb, K=src_K.float(), c2w=c2w, w2c=rigid_inverse(c2w))

    def _render_pass(self, field: SRayField, src: SourceSet, origins: Tensor, dirs: Tensor,
                     z: Tensor, near: Tensor, far: Tensor) -> dict[str, Tensor]:
        """One pass: per-sample field, then compositing. Returns the CONTRACTS.md pass dict."""
        out = field(src, origins, dirs, z)
        comp = composite(out["sigma"], z, near, far, {"logits": out["logits"], "rgb": out["rgb"]})
        return {"logits": comp["logits"], "rgb": comp["rgb"], "depth": comp["depth"],
                "opacity": comp["opacity"], "weights": comp["weights"], "z": z}

    def render_rays(self, src: SourceSet, origins: Tensor, dirs: Tensor, near: Tensor | float,
                    far: Tensor | float, stratified: bool,
                    generator: torch.Generator | None = None) -> dict[str, dict[str, Tensor]]:
        """Render rays o + t d, t in [near, far] (camera z-depth for ``pixel_rays`` directions).

        origins, dirs: (R, 3); near, far: scalars or (R,). ``stratified`` jitters coarse and fine
        samples (training); otherwise sampling is deterministic (evaluation).
        Returns ``{"coarse": pass, "fine": pass}``, a pass holding ``logits`` (R, L), ``rgb``
        (R, 3), ``depth`` (R,), ``opacity`` (R,), ``weights`` (R, N) and ``z`` (R, N).
        """
        if origins.ndim != 2 or origins.shape[-1] != 3 or dirs.shape != origins.shape:
            raise ValueError(f"sray.model.sray.render_rays: origins and dirs must both be (R, 3), got "
                             f"{tuple(origins.shape)} and {tuple(dirs.shape)}.")
        n_rays = origins.shape[0]
        origins, dirs = origins.float(), dirs.float()
        near_r, far_r = _per_ray(near, n_rays, origins), _per_ray(far, n_rays, origins)
        z_coarse = sample_uniform(near_r, far_r, self.cfg.n_coarse, stratified, generator)  # (R, Nc)
        coarse = self._render_pass(self.coarse, src, origins, dirs, z_coarse, near_r, far_r)
        z_fine = sample_pdf(z_coarse, coarse["weights"].detach(), near_r, far_r, self.cfg.n_fine,
                            deterministic=not stratified, generator=generator)  # (R, Nf)
        z_all = merge_samples(z_coarse, z_fine)  # (R, Nc + Nf)
        fine = self._render_pass(self.fine, src, origins, dirs, z_all, near_r, far_r)
        return {"coarse": coarse, "fine": fine}

    @torch.no_grad()
    def render_image(self, src: SourceSet, K: Tensor, c2w: Tensor, hw: tuple[int, int],
                     near: Tensor | float, far: Tensor | float,
                     chunk: int | None = None) -> dict[str, dict[str, Tensor]]:
        """Render a whole (H, W) query image in chunks of rays, deterministic sampling, no grad.

        K (3, 3), c2w (4, 4) of the query camera; near, far scalars. Returns ``{"coarse": ...,
        "fine": ...}`` with ``logits`` (H, W, L), ``rgb`` (H, W, 3), ``depth`` (H, W) and
        ``opacity`` (H, W) per pass. Memory is bounded by ``chunk`` rays (default ``cfg.chunk``).
        """
        h, w = hw
        step = int(chunk or self.cfg.chunk)
        if step < 1:
            raise ValueError(f"sray.model.sray.render_image: chunk must be >= 1, got {step}.")
        origins, dirs = pixel_rays(K.float(), c2w.float(), image_pixels(h, w, device=src.feats.device))
        parts: dict[str, dict[str, list[Tensor]]] = {p: {k: [] for k in IMAGE_KEYS} for p in ("coarse", "fine")}
        for start in range(0, h * w, step):
            out = self.render_rays(src, origins[start:start + step], dirs[start:start + step],
                                   near, far, stratified=False)
            for p, per_pass in parts.items():
                for k, items in per_pass.items():
                    items.append(out[p][k].float())
        return {p: {k: torch.cat(v).reshape(h, w, *v[0].shape[1:]) for k, v in per_pass.items()}
                for p, per_pass in parts.items()}
