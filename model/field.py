"""``SRayField``, the per-sample network of one render pass: context M by reprojection, CRA into M'', the semantic ray
s = sum_i w_i F''_i (bounded weights), its logits (and ``semantic_cues``), geometry-aware density and colour."""

from __future__ import annotations

import torch
from torch import Tensor, nn

from .config import SRayConfig
from .cra import CrossReprojectionAttention
from .fast_field import cra_forward, geometry_forward, weights_forward
from .geometry_net import GeometryNet
from .reprojection import ContextualSpace
from .semantic_cues import semantic_cues
from .semantic_weights import SemanticWeightNet
from .source_set import SourceSet


def normalised_depth(z: Tensor, near: Tensor, far: Tensor) -> Tensor:
    """Each sample's depth as a fraction of its ray's [near, far]: z (R, N), near/far (R,) -> (R, N) in [0, 1]."""
    return (z - near[:, None]) / (far - near).clamp_min(1e-6)[:, None]


class SRayField(nn.Module):
    """Per-sample semantics, density and colour for a fixed number of samples per ray."""

    def __init__(self, cfg: SRayConfig) -> None:
        super().__init__()
        c = cfg.feat_dim
        self.context = ContextualSpace(c, cfg.dir_hidden, cfg.min_source_depth)
        self.attention = CrossReprojectionAttention(cfg)
        self.view_weights = SemanticWeightNet(cfg)
        self.cues = tuple(cfg.semantic_cues)
        self.classifier = nn.Sequential(nn.Linear(c + len(self.cues), c), nn.ELU(), nn.Linear(c, cfg.n_classes))
        self.geometry = GeometryNet(cfg)

    def classify(self, semantic: Tensor, sigma: Tensor, depth01: Tensor, points: Tensor, dirs: Tensor) -> Tensor:
        """Per-sample logits (R, N, L) of the semantic ray (R, N, C), with the ``semantic_cues`` when there are any."""
        if not self.cues:
            return self.classifier(semantic)
        cues = semantic_cues(self.cues, sigma, depth01, points, dirs).to(semantic.dtype)
        return self.classifier(torch.cat([semantic, cues], dim=-1))

    def forward(self, src: SourceSet, origins: Tensor, dirs: Tensor, z: Tensor, near: Tensor,
                far: Tensor, impl: str) -> dict[str, Tensor]:
        """origins, dirs (R, 3), z (R, N) ray parameters, near, far (R,), ``impl`` one of ``runtime.IMPLS`` ->
        ``sigma`` (R, N) float32 >= 0 per world unit, ``logits`` (R, N, L), ``rgb`` (R, N, 3) float32 and
        ``view_weights`` (R, m, N) float32 (the semantic-aware weights)."""
        points = origins[:, None, :] + z[..., None] * dirs[:, None, :]  # (R, N, 3)
        depth01 = normalised_depth(z, near, far)  # (R, N)
        ctx = self.context(src, points, dirs, impl)
        if impl == "fast":  # the same computation in (R, N, m) order (fast_field)
            refined = cra_forward(self.attention, ctx["M"], ctx["valid"], depth01)  # (R, N, m, C)
            w = weights_forward(self.view_weights, refined, ctx["dir"], ctx["valid"])  # (R, N, m)
            semantic = (w[..., None].to(refined.dtype) * refined).sum(dim=2)  # (R, N, C)
            sigma, rgb = geometry_forward(self.geometry, ctx["M"], ctx["valid"], ctx["dir"], ctx["rgb"])
            w = w.transpose(1, 2)  # (R, m, N)
        else:
            refined = self.attention(ctx["M"], ctx["valid"], depth01)  # (R, m, N, C)
            w = self.view_weights(refined, ctx["dir"], ctx["valid"])  # (R, m, N)
            semantic = (w[..., None].to(refined.dtype) * refined).sum(dim=1)  # (R, N, C)
            sigma, rgb = self.geometry(ctx["M"], ctx["valid"], ctx["dir"], ctx["rgb"])
        logits = self.classify(semantic, sigma, depth01, points, dirs)
        return {"sigma": sigma, "logits": logits, "rgb": rgb, "view_weights": w}
