"""``SourceSet``: the encoded source views of one scene, produced once by ``SRayModel.encode``."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor


def rigid_inverse(c2w: Tensor) -> Tensor:
    """World-to-camera (..., 4, 4) of rigid camera-to-world transforms (..., 4, 4), in their dtype with autocast
    off (a bfloat16 translation is off by centimetres)."""
    rot_t = c2w[..., :3, :3].transpose(-1, -2)  # (..., 3, 3) R^T
    with torch.autocast(device_type=c2w.device.type, enabled=False):
        trans = -(rot_t @ c2w[..., :3, 3:])  # (..., 3, 1) -R^T t
    top = torch.cat([rot_t, trans], dim=-1)  # (..., 3, 4)
    bottom = torch.zeros_like(c2w[..., 3:, :])
    bottom[..., 0, 3] = 1.0
    return torch.cat([top, bottom], dim=-2)


@dataclass
class SourceSet:
    """Source-view features and cameras, encoded once and rendered against any number of times."""

    feats: Tensor
    """(m, C, h, w) encoder features; pixel (j, i) is centred on full-res pixel (4j, 4i)."""
    rgb: Tensor
    """(m, 3, H, W) source colours in [0, 1] (the colour head blends them)."""
    K: Tensor
    """(m, 3, 3) intrinsics of the full-resolution images."""
    c2w: Tensor
    """(m, 4, 4) camera-to-world, OpenCV axes."""
    w2c: Tensor
    """(m, 4, 4) world-to-camera (rigid inverse of c2w)."""
    depth: Tensor | None = None
    """(m, H, W) source z-depth in metres, 0 = unknown; only in ``inputs='rgbd'`` (``depth_sampling``)."""

    @property
    def image_hw(self) -> tuple[int, int]:
        """Full-resolution image size (H, W)."""
        return int(self.rgb.shape[-2]), int(self.rgb.shape[-1])

    @property
    def centres(self) -> Tensor:
        """(m, 3) camera centres in world coordinates."""
        return self.c2w[:, :3, 3]

    def select(self, index: Tensor | list[int]) -> "SourceSet":
        """The views at ``index`` (reorders or subsets m), sharing storage where possible."""
        idx = torch.as_tensor(index, device=self.feats.device, dtype=torch.long)
        depth = None if self.depth is None else self.depth[idx]
        return SourceSet(self.feats[idx], self.rgb[idx], self.K[idx], self.c2w[idx], self.w2c[idx], depth)
