"""``SRayModel``: the Semantic Ray network (S-Ray, CVPR 2023), pixelNeRF's encode / query split with no state kept
between the calls::

    src = model.encode(src_rgb, src_K, src_c2w)          # once per source set
    out = model.render_rays(src, origins, dirs, near, far, stratified=True)   # any number of times

One shared encoder, separate coarse and fine fields (as the paper's public code); sampling, compositing and the
whole-view loop are shared with Semantic-NeRF (``hierarchical``, ``view_render``); choices: docs/model.md."""

from __future__ import annotations

import torch
from torch import Tensor, nn

from .config import SRayConfig
from .depth_sampling import source_surface_depth, surface_samples
from .encoder import ResUNetEncoder
from .fast_render import FastRender, render_rays_fast
from .field import SRayField
from .hierarchical import CoarseSampler, PassField, per_ray_bounds, render_rays
from .losses import render_loss
from .piecewise_loss import piecewise_render_loss
from .ray_chunks import train_piece_rays
from .runtime import Runtime
from .source_semantics import SourceSemanticHead
from .source_set import SourceSet, rigid_inverse
from .view_render import RayRenderer, render_view

__all__ = ["SRayModel", "SourceSet"]


class SRayModel(nn.Module):
    """The S-Ray network: encoder, coarse and fine fields, volume rendering of semantics and colour."""

    def __init__(self, cfg: SRayConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.encoder = ResUNetEncoder(cfg.feat_dim, cfg.encoder_width)
        self.coarse = SRayField(cfg)
        self.fine = SRayField(cfg)
        self.src_head = SourceSemanticHead(cfg) if cfg.lambda_src_sem > 0 else None
        """Training-only per-pixel classifier of the source views' features (``lambda_src_sem`` > 0)."""

    def encode(self, src_rgb: Tensor, src_K: Tensor, src_c2w: Tensor, src_depth: Tensor | None = None) -> SourceSet:
        """Encode m source views once: src_rgb (m, 3, H, W) in [0, 1], src_K (m, 3, 3), src_c2w (m, 4, 4);
        src_depth (m, H, W) z-depth in metres (0 = unknown), required with ``inputs='rgbd'``, else not kept."""
        m = src_rgb.shape[0]
        if src_rgb.ndim != 4 or src_K.shape != (m, 3, 3) or src_c2w.shape != (m, 4, 4):
            raise ValueError("sray.model.semantic_ray.encode: expected src_rgb (m, 3, H, W), src_K (m, 3, 3), src_c2w "
                             f"(m, 4, 4); got {tuple(src_rgb.shape)}, {tuple(src_K.shape)}, {tuple(src_c2w.shape)}.")
        if not src_rgb.is_floating_point():
            raise ValueError(f"sray.model.semantic_ray.encode: src_rgb must be float in [0, 1], got {src_rgb.dtype}; "
                             "divide uint8 images by 255.")
        depth = None
        if self.cfg.inputs == "rgbd":
            if src_depth is None or src_depth.shape != (m, *src_rgb.shape[-2:]):
                got = None if src_depth is None else tuple(src_depth.shape)
                raise ValueError(f"sray.model.semantic_ray.encode: model.inputs is 'rgbd', so src_depth must be "
                                 f"(m, H, W) = {(m, *src_rgb.shape[-2:])} metres (0 = unknown), got {got}; pass the "
                                 "source views' depth, or use model.inputs=rgb.")
            depth = src_depth.float()
        feats = self.encoder(src_rgb)  # (m, C, H/4, W/4)
        c2w = src_c2w.float()
        return SourceSet(feats=feats, rgb=src_rgb, K=src_K.float(), c2w=c2w, w2c=rigid_inverse(c2w), depth=depth)

    def coarse_sampler(self, src: SourceSet) -> CoarseSampler | None:
        """Coarse sample placement against ``src``: None (equal bins), or by the source depths with ``rgbd``."""
        if self.cfg.inputs == "rgb":
            return None
        cfg = self.cfg

        def sampler(o: Tensor, d: Tensor, near: Tensor, far: Tensor, n: int, stratified: bool,
                    generator: torch.Generator | None) -> Tensor:
            surface = source_surface_depth(src, o, d, near, far, n, cfg.depth_band, cfg.min_source_depth)  # (R,)
            return surface_samples(near, far, surface, n, cfg.depth_fraction, cfg.depth_band, stratified, generator)

        return sampler

    def _pass_field(self, src: SourceSet, runtime: Runtime) -> PassField:
        """The ``hierarchical.PassField`` of the coarse and fine fields against ``src``, run as ``runtime.impl``."""
        fields = {"coarse": self.coarse, "fine": self.fine}
        return lambda name, o, d, z, lo, hi: fields[name](src, o, d, z, lo, hi, runtime.impl)

    def render_rays(self, src: SourceSet, origins: Tensor, dirs: Tensor, near: Tensor | float,
                    far: Tensor | float, stratified: bool, generator: torch.Generator | None = None,
                    runtime: Runtime = Runtime()) -> dict[str, dict[str, Tensor]]:
        """Render rays o + t d, t in [near, far] (z-depth for ``pixel_rays`` directions): origins, dirs (R, 3), near,
        far scalars or (R,); ``stratified`` jitters the samples (training). Returns ``hierarchical.render_rays``'."""
        return render_rays(self._pass_field(src, runtime), origins, dirs, near, far, self.cfg.n_coarse,
                           self.cfg.n_fine, stratified, generator, self.cfg.fine_samples, self.coarse_sampler(src))

    def training_loss(self, src: SourceSet, origins: Tensor, dirs: Tensor, near: Tensor | float,
                      far: Tensor | float, target_label: Tensor, target_rgb: Tensor,
                      runtime: Runtime = Runtime()) -> tuple[Tensor, dict[str, Tensor]]:
        """``render_loss`` of rays rendered with stratified samples: origins, dirs (R, 3), near, far scalars or (R,),
        target_label (R,) int64, target_rgb (R, 3). Rendered ``runtime.train_piece`` rays at a time (0: by device),
        each piece's gradient taken before the next (``piecewise_loss``): one pass's loss and gradients (float32)."""
        n_rays = origins.shape[0]
        near_r = per_ray_bounds(near, n_rays, origins, "near")  # (R,)
        far_r = per_ray_bounds(far, n_rays, origins, "far")  # (R,)
        piece = train_piece_rays(runtime.train_piece, origins.device, n_rays)
        if piece >= n_rays:
            out = self.render_rays(src, origins, dirs, near, far, stratified=True, runtime=runtime)
            return render_loss(out, target_label, target_rgb, self.cfg)

        def render(piece_src: SourceSet, sl: slice) -> dict[str, dict[str, Tensor]]:
            return self.render_rays(piece_src, origins[sl], dirs[sl], near_r[sl], far_r[sl], stratified=True,
                                    runtime=runtime)

        params = [p for name, p in self.named_parameters() if not name.startswith("encoder.")]
        return piecewise_render_loss(render, src, params, n_rays, piece, target_label, target_rgb, self.cfg)

    @torch.no_grad()
    def render_rays_fast(self, src: SourceSet, origins: Tensor, dirs: Tensor, near: Tensor | float,
                         far: Tensor | float, confidence: float,
                         runtime: Runtime = Runtime(), temperature: float = 1.0) -> dict[str, dict[str, Tensor]]:
        """The fast mode's rays (``fast_render.render_rays_fast``): a fine pass below ``confidence`` only."""
        return render_rays_fast(self._pass_field(src, runtime), origins, dirs, near, far, self.cfg.n_coarse,
                                self.cfg.n_fine, confidence, self.coarse_sampler(src), temperature)

    def ray_renderer(self, src: SourceSet, fast: FastRender | None = None, runtime: Runtime = Runtime()) -> RayRenderer:
        """A deterministic ``view_render.RayRenderer`` bound to ``src``: the full render, or the fast mode's rays."""
        if fast is not None:
            return lambda o, d, near, far: self.render_rays_fast(src, o, d, near, far, fast.confidence, runtime,
                                                                 fast.temperature)
        return lambda o, d, near, far: self.render_rays(src, o, d, near, far, stratified=False, runtime=runtime)

    def render_image(self, src: SourceSet, K: Tensor, c2w: Tensor, hw: tuple[int, int], near: float, far: float,
                     runtime: Runtime = Runtime(), stride: int = 1,
                     fast: FastRender | None = None) -> dict[str, dict[str, Tensor]]:
        """``view_render.render_view`` of the query camera K (3, 3), c2w (4, 4) against ``src``."""
        return render_view(self.ray_renderer(src, fast, runtime), K, c2w, hw, near, far, runtime.chunk,
                           src.feats.device, stride, fast)
