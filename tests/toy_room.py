"""A tiny ray-cast room and a short S-Ray overfit on it, shared by the model tests.

The room is closed by six axis-aligned planes and holds a crate standing on the floor (OpenCV world:
y points down). Every pixel is intersected exactly, so colours and labels agree across views. Five
labels: floor 0, walls along z 1, walls along x 2, ceiling 3, crate 4.

Import from a test module with ``import toy_room`` (tests/conftest.py puts tests/ on sys.path).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import torch

from sray.model.config import SRayConfig
from sray.model.losses import render_loss
from sray.model.rays import image_pixels, pixel_rays
from sray.model.semantic_ray import SRayModel

N_CLASSES = 5
NEAR, FAR = 0.5, 6.0
# axis-aligned planes (axis, coordinate, label) closing a room; OpenCV world: y points down
PLANES = [(1, 0.8, 0), (1, -1.2, 3), (2, 4.0, 1), (2, -1.0, 1), (0, -1.6, 2), (0, 1.6, 2)]
BOX = (np.array([-0.5, 0.0, 2.2]), np.array([0.4, 0.8, 3.0]), 4)  # a crate standing on the floor
COLOURS = np.array([[0.6, 0.4, 0.2], [0.8, 0.8, 0.7], [0.3, 0.5, 0.8], [0.9, 0.9, 0.9], [0.8, 0.2, 0.2]])
TARGET = np.array([0.0, 0.2, 3.0])
POSITIONS = [(-0.6, -0.2), (0.6, -0.2), (-0.5, 0.3), (0.5, 0.3), (0.0, 0.0), (0.15, -0.1)]
"""Camera (x, y) at z = 0, all looking at TARGET: views 0-3 are the sources, 4-5 the training views."""
SOURCE_IDS, TRAIN_IDS = [0, 1, 2, 3], [4, 5]


def look_at(pos: np.ndarray, target: np.ndarray) -> np.ndarray:
    """OpenCV camera-to-world at ``pos`` looking at ``target`` (y down)."""
    fwd = (target - pos) / np.linalg.norm(target - pos)
    right = np.cross([0.0, 1.0, 0.0], fwd)
    right /= np.linalg.norm(right)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([right, np.cross(fwd, right), fwd], 1)
    c2w[:3, 3] = pos
    return c2w


def first_hits(K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int],
                offset: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact first intersections of the pixel rays of ``c2w``: ray parameter t (H*W,) (the camera z-depth,
    as ``pixel_rays`` directions have camera z 1), label (H*W,), origins and directions (H*W, 3) in room
    coordinates (the room moved by ``offset``)."""
    rays = pixel_rays(torch.tensor(K), torch.tensor(c2w), image_pixels(*hw).double())
    o, d = (t.numpy() for t in rays)  # (H*W, 3) float64
    o = o - offset  # room coordinates
    best_t = np.full(len(d), np.inf)
    label = np.zeros(len(d), dtype=np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, coord, lab in PLANES:
            t = (coord - o[:, axis]) / d[:, axis]
            hit = (t > 1e-6) & (t < best_t)
            best_t, label = np.where(hit, t, best_t), np.where(hit, lab, label)
        lo, hi, lab = BOX
        t0, t1 = (lo - o) / d, (hi - o) / d
        t_in = np.minimum(t0, t1).max(1)
        t_out = np.maximum(t0, t1).min(1)
        hit = (t_in <= t_out) & (t_in > 1e-6) & (t_in < best_t)
        best_t, label = np.where(hit, t_in, best_t), np.where(hit, lab, label)
    return best_t, label, o, d


def ray_cast(K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int],
             offset: np.ndarray = np.zeros(3)) -> tuple[np.ndarray, np.ndarray]:
    """Render (H, W, 3) colours and (H, W) labels of the room seen from ``c2w`` (exact intersections),
    with the room moved by ``offset`` (3,) in the world."""
    h, w = hw
    best_t, label, o, d = first_hits(K, c2w, hw, offset)
    p = o + best_t[:, None] * d
    checker = (np.floor(p[:, 0] * 3) + np.floor(p[:, 1] * 3) + np.floor(p[:, 2] * 3)) % 2
    rgb = COLOURS[label] * (0.75 + 0.25 * checker[:, None])
    return rgb.reshape(h, w, 3), label.reshape(h, w)


def miou(pred: np.ndarray, gt: np.ndarray, n: int) -> float:
    """Mean IoU over classes present in gt, from one hand-made confusion matrix."""
    conf = np.zeros((n, n), dtype=np.int64)
    np.add.at(conf, (gt.ravel(), pred.ravel()), 1)
    inter = np.diag(conf)
    union = conf.sum(0) + conf.sum(1) - inter
    present = conf.sum(1) > 0
    return float((inter[present] / union[present]).mean())


@contextmanager
def one_thread() -> Iterator[None]:
    """Run on one intra-op thread: hundreds of small steps stall badly on a shared 2-core machine
    when two OpenMP threads wait on each other; restored afterwards."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@dataclass
class ToyRoom:
    """The room seen by the cameras of ``POSITIONS`` at one image size."""

    K: np.ndarray
    """(3, 3) intrinsics shared by every view, float64."""
    hw: tuple[int, int]
    """Image size (H, W)."""
    cams: list[np.ndarray]
    """(4, 4) camera-to-world of every view, float64."""
    views: list[tuple[np.ndarray, np.ndarray]]
    """Ray-cast (H, W, 3) colours and (H, W) labels of every view."""

    def sources(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """float32 source images (m, 3, H, W), K (m, 3, 3) and c2w (m, 4, 4) of ``SOURCE_IDS``."""
        rgb = torch.tensor(np.stack([self.views[i][0] for i in SOURCE_IDS]), dtype=torch.float32)
        K = torch.tensor(self.K, dtype=torch.float32).expand(len(SOURCE_IDS), 3, 3)
        c2w = torch.tensor(np.stack([self.cams[i] for i in SOURCE_IDS]), dtype=torch.float32)
        return rgb.permute(0, 3, 1, 2), K, c2w

    def source_depth(self) -> torch.Tensor:
        """float32 (m, H, W) exact z-depth of the ``SOURCE_IDS`` views (the room is closed: no unknown pixel)."""
        depth = [first_hits(self.K, self.cams[i], self.hw, np.zeros(3))[0].reshape(self.hw) for i in SOURCE_IDS]
        return torch.tensor(np.stack(depth), dtype=torch.float32)


def make_room(hw: tuple[int, int], focal: float, offset: np.ndarray = np.zeros(3)) -> ToyRoom:
    """Ray-cast every view of the room, moved by ``offset`` (3,) in the world, at size ``hw`` with
    fx = fy = ``focal`` and a centred principal point."""
    h, w = hw
    K = np.array([[focal, 0.0, (w - 1) / 2], [0.0, focal, (h - 1) / 2], [0.0, 0.0, 1.0]])
    cams = [look_at(np.array([x, y, 0.0]) + offset, TARGET + offset) for x, y in POSITIONS]
    return ToyRoom(K=K, hw=hw, cams=cams, views=[ray_cast(K, c, hw, offset) for c in cams])


def overfit(room: ToyRoom, cfg: SRayConfig, steps: int, rays_per_step: int = 128) -> SRayModel:
    """Train an S-Ray model from seed 0 on the training views of ``room`` (Adam, lr 3e-3 decaying
    linearly to 3e-4), in float32; returns it in eval mode."""
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    h, w = room.hw
    src_rgb, src_K, src_c2w = room.sources()
    src_depth = room.source_depth() if cfg.inputs == "rgbd" else None
    net = SRayModel(cfg)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: 1.0 - 0.9 * s / steps)
    pixels = image_pixels(h, w)
    K = torch.tensor(room.K, dtype=torch.float32)
    for step in range(steps):
        q = TRAIN_IDS[step % len(TRAIN_IDS)]
        pick = torch.tensor(rng.choice(h * w, rays_per_step, replace=False))
        origins, dirs = pixel_rays(K, torch.tensor(room.cams[q], dtype=torch.float32), pixels[pick])
        src = net.encode(src_rgb, src_K, src_c2w, src_depth)
        out = net.render_rays(src, origins, dirs, NEAR, FAR, stratified=True)
        label = torch.tensor(room.views[q][1].reshape(-1)[pick.numpy()])
        rgb = torch.tensor(room.views[q][0].reshape(-1, 3)[pick.numpy()], dtype=torch.float32)
        loss, _ = render_loss(out, label, rgb, cfg)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
    return net.eval()
