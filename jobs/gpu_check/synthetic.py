"""Seeded synthetic inputs of the checks (random images suffice where a check compares two computations of the same
thing): a camera rig, source images, training samples and a toy procedural world."""

from __future__ import annotations

import math

import torch

from sray.data_tools.loader.sample_types import QueryCamera, SourceViews, TrainSample
from sray.data_tools.synth.world import World
from sray.model.config import SRayConfig
from sray.model.semantic_ray import SRayModel


def pinhole(hw: tuple[int, int], fov_deg: float) -> torch.Tensor:
    """(3, 3) intrinsics of an (H, W) image with horizontal field of view ``fov_deg``, centred principal point."""
    h, w = hw
    f = (w / 2) / math.tan(math.radians(fov_deg) / 2)
    return torch.tensor([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])


def rig(views: int, hw: tuple[int, int], device: torch.device, seed: int = 0) -> tuple[SourceViews, QueryCamera]:
    """Source views (m, 3, H, W) with K (m, 3, 3) and c2w (m, 4, 4) spread around a query camera at the origin."""
    gen = torch.Generator().manual_seed(seed)
    K = pinhole(hw, 60.0)
    c2w = torch.eye(4).repeat(views, 1, 1)
    c2w[:, 0, 3] = torch.linspace(-0.3, 0.3, views)
    c2w[:, 1, 3] = 0.1 * torch.sin(torch.arange(views, dtype=torch.float32))
    sources = SourceViews(rgb=torch.rand(views, 3, *hw, generator=gen), K=K.expand(views, 3, 3).clone(), c2w=c2w)
    return sources.to(device), QueryCamera(K=K, c2w=torch.eye(4)).to(device)


def training_sample(views: int, hw: tuple[int, int], rays: int, n_classes: int, device: torch.device,
                    seed: int = 0) -> TrainSample:
    """A training sample as the loader makes it (bounds 1-5 m), on ``device``."""
    gen = torch.Generator().manual_seed(seed + 1)
    h, w = hw
    sources, query = rig(views, hw, device, seed)
    return TrainSample(scene="synthetic", query_id="query", sources=sources, query=query, near=1.0, far=5.0,
                       pixels=(torch.rand(rays, 2, generator=gen) * torch.tensor([w - 1.0, h - 1.0])).to(device),
                       target_label=torch.randint(0, n_classes, (rays,), generator=gen).to(device),
                       target_rgb=torch.rand(rays, 3, generator=gen).to(device))


def model(samples: tuple[int, int], views: int, device: torch.device, seed: int = 0) -> SRayModel:
    """A seeded S-Ray model of the paper's widths with the given (coarse, fine) samples."""
    torch.manual_seed(seed)
    return SRayModel(SRayConfig(n_coarse=samples[0], n_fine=samples[1], n_source=views)).to(device)


def toy_world(dry_run: bool, train_scenes: int = 2, test_scenes: int = 1) -> World:
    """A procedural world of 20 views per room and 8 ranked neighbours, 120 x 160 pixels (48 x 64 in a dry run: the
    recipe draws sources down to 75% size, 32 pixels at least)."""
    hw = (48, 64) if dry_run else (120, 160)
    return World(train_scenes=train_scenes, test_scenes=test_scenes, views=20, height=hw[0], width=hw[1], seed=0,
                 neighbours=8)
