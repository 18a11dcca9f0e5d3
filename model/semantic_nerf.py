"""Semantic-NeRF baseline (Zhi et al., ICCV 2021) from the paper's description: a per-scene NeRF (positions
normalised by the scene box, unit directions; NeRF's encoding with 10 and 4 frequencies + raw) whose 8 x 256 ReLU
trunk, re-reading the encoded position after its fifth layer, feeds density (softplus, not NeRF's ReLU, so rays cannot
die empty at initialisation), semantics (-> 128 -> L logits, before the direction enters: labels do not depend on
the viewpoint) and colour (256-wide feature + encoded direction -> 128 -> sigmoid rgb). Coarse and fine networks,
the fine one on the union of coarse and resampled depths; renderer, losses and metrics are S-Ray's."""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from sray.model.hierarchical import render_rays
from sray.model.positional_encoding import PositionalEncoding
from sray.model.view_render import render_view


@dataclass
class SemanticNeRFConfig:
    """Semantic-NeRF hyper-parameters (defaults: the paper's, except ``n_fine``)."""

    n_classes: int
    """Number of semantic classes L of the scene's label space (the ignore id is not a class)."""
    pos_freqs: int = 10
    """Positional-encoding frequencies of the position."""
    dir_freqs: int = 4
    """Positional-encoding frequencies of the viewing direction."""
    depth: int = 8
    """Number of trunk layers."""
    width: int = 256
    """Width of the trunk layers."""
    skip_layer: int | None = 5
    """0-based trunk layer that re-reads the encoded position (5 = after the fifth layer, as NeRF); None: no skip."""
    color_width: int = 128
    """Hidden width of the colour head."""
    semantic_width: int = 128
    """Hidden width of the semantic head."""
    n_coarse: int = 64
    """Coarse samples per ray (stratified in training, bin centres otherwise)."""
    n_fine: int = 64
    """Fine samples per ray drawn from the coarse weights (the paper uses 128)."""
    lambda_sem: float = 1.0
    """Weight of the semantic cross-entropy in ``sray.model.losses.render_loss``."""
    lambda_rgb: float = 1.0
    """Weight of the photometric MSE."""
    ignore_id: int = 255
    """Label id of unlabelled pixels."""
    chunk: int = 4096
    """Rays per forward pass in ``render_image``."""
    scene_center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """World point mapped to the origin before the positional encoding (``scene_box_from_cameras``)."""
    scene_scale: float = 1.0
    """World length mapped to 1: the encoding reads (x - center) / scale, about [-1, 1]. Densities stay per world
    unit (NeRF's convention; per normalised unit they would need ``scale`` times larger values)."""

    def __post_init__(self) -> None:
        """Reject settings the network cannot run with, naming the field."""

        def fail(field: str, why: str) -> None:
            raise ValueError(f"sray.model.semantic_nerf.SemanticNeRFConfig.{field}: {why}")

        if self.n_classes < 1:
            fail("n_classes", f"must be >= 1, got {self.n_classes}")
        if self.depth < 1 or self.width < 1:
            fail("depth", f"depth and width must be >= 1, got {self.depth} and {self.width}")
        if self.skip_layer is not None and not 0 < self.skip_layer < self.depth:
            fail("skip_layer", f"must be in [1, {self.depth - 1}] or None, got {self.skip_layer}")
        if self.n_coarse < 1 or self.n_fine < 1:
            fail("n_coarse", f"n_coarse and n_fine must be >= 1, got {self.n_coarse}, {self.n_fine}")
        if self.scene_scale <= 0:
            fail("scene_scale", f"must be > 0, got {self.scene_scale}")
        if self.chunk < 1:
            fail("chunk", f"must be >= 1, got {self.chunk}")


class SemanticNeRFField(nn.Module):
    """One Semantic-NeRF MLP: (normalised position, unit direction) -> density, rgb, logits."""

    def __init__(self, cfg: SemanticNeRFConfig) -> None:
        super().__init__()
        self.skip_layer = cfg.skip_layer
        self.pos_enc = PositionalEncoding(3, cfg.pos_freqs)
        self.dir_enc = PositionalEncoding(3, cfg.dir_freqs)
        pos_dim = self.pos_enc.out_dim
        self.trunk = nn.ModuleList(
            nn.Linear((pos_dim if i == 0 else cfg.width) + (pos_dim if i == cfg.skip_layer else 0), cfg.width)
            for i in range(cfg.depth))
        self.density = nn.Linear(cfg.width, 1)
        self.semantic = nn.Sequential(
            nn.Linear(cfg.width, cfg.semantic_width), nn.ReLU(),
            nn.Linear(cfg.semantic_width, cfg.n_classes),
        )
        self.feature = nn.Linear(cfg.width, cfg.width)
        self.color = nn.Sequential(nn.Linear(cfg.width + self.dir_enc.out_dim, cfg.color_width), nn.ReLU(),
                                   nn.Linear(cfg.color_width, 3))

    def forward(self, x: Tensor, d: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """x (..., 3) normalised, d (..., 3) unit -> density (...,) per world unit, rgb (..., 3), logits (..., L)."""
        gamma_x = self.pos_enc(x)
        h = gamma_x
        for i, layer in enumerate(self.trunk):
            if i == self.skip_layer:
                h = torch.cat([h, gamma_x], dim=-1)
            h = F.relu(layer(h))
        sigma = F.softplus(self.density(h)).squeeze(-1)
        logits = self.semantic(h)
        rgb = torch.sigmoid(self.color(torch.cat([self.feature(h), self.dir_enc(d)], dim=-1)))
        return sigma, rgb, logits


class SemanticNeRF(nn.Module):
    """Coarse + fine Semantic-NeRF of one scene; ``render_rays`` follows docs/CONTRACTS.md."""

    scene_center: Tensor
    scene_scale: Tensor

    def __init__(self, cfg: SemanticNeRFConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.coarse = SemanticNeRFField(cfg)
        self.fine = SemanticNeRFField(cfg)
        self.register_buffer("scene_center", torch.tensor(cfg.scene_center, dtype=torch.float32))
        self.register_buffer("scene_scale", torch.tensor(float(cfg.scene_scale)))

    def _field(self, name: str, origins: Tensor, dirs: Tensor, z: Tensor, near: Tensor,
               far: Tensor) -> dict[str, Tensor]:
        """The ``hierarchical.PassField`` of pass ``name``: density per world unit, colour, logits at z (R, N)."""
        pts = origins[:, None, :] + z[..., None] * dirs[:, None, :]  # (R, N, 3)
        x = (pts - self.scene_center) / self.scene_scale
        unit = F.normalize(dirs, dim=-1)[:, None, :].expand_as(pts)  # (R, N, 3)
        sigma, rgb, logits = (self.coarse if name == "coarse" else self.fine)(x, unit)
        return {"sigma": sigma, "rgb": rgb, "logits": logits}

    def render_rays(self, origins: Tensor, dirs: Tensor, near: Tensor | float, far: Tensor | float,
                    stratified: bool, generator: torch.Generator | None = None) -> dict[str, dict[str, Tensor]]:
        """Render rays o + t d, t in [near, far] (``hierarchical.render_rays``); ``stratified`` in training."""
        return render_rays(self._field, origins, dirs, near, far, self.cfg.n_coarse, self.cfg.n_fine,
                           stratified, generator, fine_samples="union")  # NeRF's rule, as Semantic-NeRF

    def render_image(self, K: Tensor, c2w: Tensor, hw: tuple[int, int], near: float, far: float,
                     chunk: int | None = None, stride: int = 1) -> dict[str, dict[str, Tensor]]:
        """``view_render.render_view`` of every ``stride``-th pixel of the (H, W) = ``hw`` view of camera K (3, 3), c2w
        (4, 4) (OpenCV axes), scalar z-depth bounds near, far, ``chunk`` rays at a time (default ``cfg.chunk``)."""
        chunk = self.cfg.chunk if chunk is None else chunk
        return render_view(lambda o, d, lo, hi: self.render_rays(o, d, lo, hi, stratified=False), K, c2w, hw, near,
                           far, chunk, self.scene_center.device, stride)


def scene_box_from_cameras(K: Tensor, c2w: Tensor, hw: tuple[int, int], near: float,
                           far: float) -> tuple[tuple[float, float, float], float]:
    """``scene_center`` and ``scene_scale`` (half the longest side) of the axis-aligned box around every camera
    frustum between z-depths near and far: K (V, 3, 3) or (3, 3), c2w (V, 4, 4) OpenCV axes, hw the image size."""
    height, width = hw
    c2w = c2w.double().reshape(-1, 4, 4)
    K = K.double().expand(c2w.shape[0], 3, 3)
    corners_px = torch.tensor([[-0.5, -0.5, 1.0], [width - 0.5, -0.5, 1.0], [-0.5, height - 0.5, 1.0],
                               [width - 0.5, height - 0.5, 1.0]], dtype=torch.float64)  # (4, 3) homogeneous pixels
    cam = torch.einsum("vij,cj->vci", torch.linalg.inv(K), corners_px)  # (V, 4, 3), z = 1
    cam = torch.cat([cam * near, cam * far], dim=1)  # (V, 8, 3) frustum corners
    world = torch.einsum("vij,vcj->vci", c2w[:, :3, :3], cam) + c2w[:, None, :3, 3]
    pts = world.reshape(-1, 3)
    lo, hi = pts.min(0).values, pts.max(0).values
    center = (lo + hi) / 2
    scale = float((hi - lo).max() / 2)
    return (float(center[0]), float(center[1]), float(center[2])), max(scale, 1e-6)
