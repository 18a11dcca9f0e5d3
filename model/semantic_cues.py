"""Appearance-free cues for the semantic head (``SRayConfig.semantic_cues``, off by default; a departure from the
paper, docs/model.md "Cues that do not depend on the look"): ``density`` log(1 + sigma) (detached), ``depth`` the
sample's fraction of [near, far], ``height`` its world z (z up, floor near 0), ``elevation`` the vertical component
of the ray's unit direction. Orientation from depth gradients would need neighbouring rays."""

from __future__ import annotations

import torch
from torch import Tensor

CUES = ("density", "depth", "height", "elevation")
"""Names of the cues, in the order they are stacked."""


def check_cues(cues: tuple[str, ...]) -> None:
    """ValueError naming an unknown or repeated cue and the valid names."""
    unknown = [c for c in cues if c not in CUES]
    if unknown or len(set(cues)) != len(cues):
        raise ValueError(f"semantic_cues {cues!r}: use distinct names from {CUES} (empty = the paper's head)")


def semantic_cues(cues: tuple[str, ...], sigma: Tensor, depth01: Tensor, points: Tensor, dirs: Tensor) -> Tensor:
    """The asked cues in :data:`CUES` order: sigma, depth01 (R, N), points (R, N, 3), dirs (R, 3) -> (R, N, k)."""
    elevation = dirs[:, 2] / dirs.norm(dim=-1).clamp_min(1e-9)  # (R,)
    values = {"density": torch.log1p(sigma.detach().float().clamp_min(0.0)), "depth": depth01.float(),
              "height": points[..., 2].float(), "elevation": elevation[:, None].expand_as(depth01).float()}
    return torch.stack([values[c] for c in CUES if c in cues], dim=-1)
