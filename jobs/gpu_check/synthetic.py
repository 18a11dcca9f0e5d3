"""Synthetic inputs of the model-level checks: a camera rig, source images and training samples.

Random images are enough where a check compares two computations of the same thing (fp32 against a
low precision, a timing); every tensor is drawn from a seeded generator, so runs repeat.
"""

from __future__ import annotations

import math

import torch

from sray.model.config import SRayConfig
from sray.model.semantic_ray import SRayModel


def pinhole(hw: tuple[int, int], fov_deg: float) -> torch.Tensor:
    """(3, 3) intrinsics of an (H, W) image with horizontal field of view ``fov_deg``, centred principal point."""
    h, w = hw
    f = (w / 2) / math.tan(math.radians(fov_deg) / 2)
    return torch.tensor([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])


def rig(views: int, hw: tuple[int, int], device: torch.device, seed: int = 0) -> dict[str, torch.Tensor]:
    """Source views (m, 3, H, W) with K (m, 3, 3) and c2w (m, 4, 4) spread around a query at the origin."""
    gen = torch.Generator().manual_seed(seed)
    K = pinhole(hw, 60.0)
    c2w = torch.eye(4).repeat(views, 1, 1)
    c2w[:, 0, 3] = torch.linspace(-0.3, 0.3, views)
    c2w[:, 1, 3] = 0.1 * torch.sin(torch.arange(views, dtype=torch.float32))
    data = {"src_rgb": torch.rand(views, 3, *hw, generator=gen), "src_K": K.expand(views, 3, 3).clone(),
            "src_c2w": c2w, "query_K": K, "query_c2w": torch.eye(4)}
    return {k: v.to(device) for k, v in data.items()}


def training_sample(views: int, hw: tuple[int, int], rays: int, n_classes: int, device: torch.device,
                    seed: int = 0) -> dict[str, torch.Tensor]:
    """A training sample in the loader's format (docs/CONTRACTS.md), on ``device``."""
    gen = torch.Generator().manual_seed(seed + 1)
    h, w = hw
    sample = rig(views, hw, device, seed)
    extra = {"pixels": torch.rand(rays, 2, generator=gen) * torch.tensor([w - 1.0, h - 1.0]),
             "target_label": torch.randint(0, n_classes, (rays,), generator=gen),
             "target_rgb": torch.rand(rays, 3, generator=gen), "near": torch.tensor(1.0), "far": torch.tensor(5.0)}
    return sample | {k: v.to(device) for k, v in extra.items()}


def model(samples: tuple[int, int], views: int, device: torch.device, seed: int = 0) -> SRayModel:
    """A seeded S-Ray model of the paper's widths with the given (coarse, fine) samples."""
    torch.manual_seed(seed)
    return SRayModel(SRayConfig(n_coarse=samples[0], n_fine=samples[1], n_source=views)).to(device)
