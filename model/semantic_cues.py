"""Appearance-free cues for the semantic head (``SRayConfig.semantic_cues``; a departure from the paper, off by
default, docs/model.md "Cues that do not depend on the look").

The paper's head classifies the semantic ray s = sum_i w_i F''_i alone. With cues on, each sample's classifier also
reads quantities that no colour enters except through the density the field estimates, or that the poses give:

* ``density``: log(1 + sigma) of the sample, the field's own density (detached: the semantic loss does not train
  the density through this input);
* ``depth``: the sample's depth along its ray as a fraction of [near, far];
* ``height``: the sample's height along gravity, its world z in scene units (sray's procedural scenes and ScanNet's
  aligned scans put z up with the floor near 0);
* ``elevation``: the vertical component of the ray's unit direction (where the camera looks: down at the floor, level
  at the walls).

Surface orientation from a depth gradient needs neighbouring rays, which a training batch of random pixels does not
have; ``height`` and ``elevation`` are the pose-given cues used instead.
"""

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
    """The asked cues stacked in :data:`CUES` order: sigma (R, N), depth01 (R, N), points (R, N, 3) world, dirs (R, 3)
    -> (R, N, len(cues)) float32."""
    elevation = dirs[:, 2] / dirs.norm(dim=-1).clamp_min(1e-9)  # (R,)
    values = {"density": torch.log1p(sigma.detach().float().clamp_min(0.0)), "depth": depth01.float(),
              "height": points[..., 2].float(), "elevation": elevation[:, None].expand_as(depth01).float()}
    return torch.stack([values[c] for c in CUES if c in cues], dim=-1)
