"""``sray.load(checkpoint)``: a trained S-Ray model that labels posed photos given as NumPy arrays (docs/capture.md),
each frame rendered from its ``n_source`` best other frames, ranked by the shards' rule for a camera without depth
(``neighbours.rank_camera``, at depth sqrt(near * far)). ``sray label`` calls this on a shard folder's views."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from sray.data_tools.check.rules import intrinsics_problems, pose_problems
from sray.data_tools.loader.sample_types import QueryCamera, SceneQuery, SourceViews
from sray.data_tools.shards.neighbours import grid_points, grid_samples, rank_camera
from sray.model.fast_render import FastRender
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.folders import resolve_checkpoint
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.render.frames import render_frame

INDOOR_RANGE = (0.1, 10.0)  # depth range (metres) used when ``label`` is given none: a room seen from inside it


@dataclass(frozen=True)
class Labels:
    """What :meth:`Labeller.label` returns: ``label`` uint8 (N, H, W) class ids of the model's label space,
    ``confidence`` float32 (N, H, W) largest softmax probability, ``depth`` float32 (N, H, W) rendered z-depth in
    metres, ``rgb`` uint8 (N, H, W, 3) rendered colour, ``sources`` each frame's source indices, best first."""

    label: np.ndarray
    confidence: np.ndarray
    depth: np.ndarray
    rgb: np.ndarray
    sources: list[list[int]]


def _check_inputs(images: np.ndarray, poses: np.ndarray, intrinsics: np.ndarray,
                  depth_range: tuple[float, float]) -> np.ndarray:
    """ValueError naming the argument on bad input; returns the intrinsics as (N, 3, 3) float64."""
    if not isinstance(images, np.ndarray) or images.dtype != np.uint8 or images.ndim != 4 or images.shape[3] != 3:
        raise ValueError(f"images must be a uint8 array (N, H, W, 3), got {getattr(images, 'dtype', type(images))} "
                         f"{getattr(images, 'shape', '')}")
    n, h, w = images.shape[:3]
    poses = np.asarray(poses, np.float64)
    if poses.shape != (n, 4, 4):
        raise ValueError(f"poses must be (N, 4, 4) = ({n}, 4, 4) camera-to-world matrices, got {poses.shape}")
    Ks = np.asarray(intrinsics, np.float64)
    Ks = np.repeat(Ks[None], n, axis=0) if Ks.shape == (3, 3) else Ks
    if Ks.shape != (n, 3, 3):
        raise ValueError(f"intrinsics must be (3, 3) or (N, 3, 3) = ({n}, 3, 3), got {np.shape(intrinsics)}")
    for i in range(n):
        problems = pose_problems(poses[i], "poses", str(i), 1e-4) + \
            intrinsics_problems(Ks[i], (h, w), "intrinsics", str(i), 0.5)
        if problems:
            raise ValueError(f"{problems[0].file}[{i}]: {problems[0].what.split(': ', 1)[-1]} (OpenCV axes, "
                             "pixel (u, v) centred at (u, v))")
    near, far = depth_range
    if not 0 < near < far or not np.isfinite(far):
        raise ValueError(f"depth_range must be (near, far) in metres with 0 < near < far, got {depth_range}")
    return Ks


class Labeller:
    """A trained S-Ray model ready to label posed photos (module doc for the conventions)."""

    def __init__(self, net: SRayModel, n_source: int = 8, fast: FastRender | None = FastRender(),
                 device: str | None = None, about: dict | None = None) -> None:
        """``net`` must read RGB; ``fast`` None: full render; ``device`` None: cuda or CPU; ``about``: provenance."""
        if net.cfg.inputs != "rgb":
            raise ValueError(f"this checkpoint reads source {net.cfg.inputs!r}; sray.load labels RGB photos with a "
                             "model trained on RGB inputs")
        self.net, self.n_source, self.fast, self.runtime = net.eval(), n_source, fast, Runtime()
        self.device = torch.device(device or ("cuda" if torch.cuda.is_available() else "cpu"))
        self.about = dict(about or {})
        self.net.to(self.device)

    @property
    def n_classes(self) -> int:
        """Classes the model predicts."""
        return int(self.net.cfg.n_classes)

    def rank_sources(self, Ks: np.ndarray, poses: np.ndarray, hw: tuple[int, int], depth: float) -> list[list[int]]:
        """Per frame, the indices of its ``n_source`` best other frames (module doc), best first."""
        n = len(poses)
        if not 1 <= self.n_source <= n - 1:
            raise ValueError(f"n_source is {self.n_source}, but {n} frames give each frame {n - 1} others; pass "
                             "between 1 and that")
        grid = grid_samples(np.zeros(hw, np.float32))
        points = [grid_points(grid, Ks[i], poses[i], depth) for i in range(n)]
        out = []
        for i in range(n):
            others = [j for j in range(n) if j != i]
            order, _ = rank_camera(Ks[i], poses[i], hw, poses[others], [points[j] for j in others], self.n_source)
            out.append([others[k] for k in order])
        return out

    @torch.no_grad()
    def label(self, images: np.ndarray, poses: np.ndarray, intrinsics: np.ndarray,
              depth_range: tuple[float, float] | None = None,
              on_frame: Callable[[int], None] | None = None) -> Labels:
        """Label a posed capture: images uint8 (N, H, W, 3) RGB; poses (N, 4, 4) OpenCV camera-to-world, metres;
        intrinsics (3, 3) or (N, 3, 3), pixel (u, v) centred at (u, v); depth_range (near, far) metres (None:
        :data:`INDOOR_RANGE`); ``on_frame(i)`` after frame i. ValueError names the argument on bad input."""
        near, far = depth_range or INDOOR_RANGE
        Ks = _check_inputs(images, poses, intrinsics, (near, far))
        poses = np.asarray(poses, np.float64)
        hw = images.shape[1:3]
        ranked = self.rank_sources(Ks, poses, hw, float(np.sqrt(near * far)))
        rgb_t = torch.from_numpy(images).permute(0, 3, 1, 2).float().div_(255.0)       # (N, 3, H, W)
        K_t, c2w_t = torch.from_numpy(Ks).float(), torch.from_numpy(poses).float()
        frames = []
        for i, ids in enumerate(ranked):
            sources = SourceViews(rgb=rgb_t[ids], K=K_t[ids], c2w=c2w_t[ids])
            sample = SceneQuery(scene="capture", query_id=str(i), sources=sources,
                                query=QueryCamera(K=K_t[i], c2w=c2w_t[i]), near=float(near), far=float(far))
            src = sources.to(self.device)
            renderer = self.net.ray_renderer(self.net.encode(src.rgb, src.K, src.c2w), self.fast, self.runtime)
            frame = render_frame(renderer, sample, hw, self.runtime.chunk, self.device, self.fast)
            frames.append((frame.label.numpy().astype(np.uint8), frame.confidence.numpy().astype(np.float32),
                           frame.depth.numpy().astype(np.float32),
                           (frame.rgb.clamp(0, 1).numpy() * 255 + 0.5).astype(np.uint8)))
            if on_frame is not None:
                on_frame(i)
        return Labels(*(np.stack(parts) for parts in zip(*frames)), sources=ranked)


def load(checkpoint: str | Path, n_source: int = 8, render: str = "fast", device: str | None = None) -> Labeller:
    """The :class:`Labeller` of a checkpoint (folder, job ``checkpoints/`` or job); ``render``: ``fast`` or ``full``."""
    if render not in ("fast", "full"):
        raise ValueError(f"render must be 'fast' or 'full', got {render!r}")
    folder = resolve_checkpoint(Path(checkpoint))
    net, _ = model_from_checkpoint(folder)
    return Labeller(net, n_source, FastRender() if render == "fast" else None, device, {"checkpoint": str(folder)})
