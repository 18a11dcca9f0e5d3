"""S-Ray overfits a tiny ray-cast room: a training view renders with mIoU above 0.9."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
import torch

from sray.model.config import SRayConfig
from sray.model.losses import render_loss
from sray.model.rays import image_pixels, pixel_rays
from sray.model.sray import SRayModel

H, W, NEAR, FAR = 36, 48, 0.5, 6.0
STEPS = 120  # 128 rays, 8 + 8 samples, 4 source views per step
K = np.array([[30.0, 0.0, (W - 1) / 2], [0.0, 30.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
# axis-aligned planes (axis, coordinate, label) closing a room; OpenCV world: y points down
PLANES = [(1, 0.8, 0), (1, -1.2, 3), (2, 4.0, 1), (2, -1.0, 1), (0, -1.6, 2), (0, 1.6, 2)]
BOX = (np.array([-0.5, 0.0, 2.2]), np.array([0.4, 0.8, 3.0]), 4)  # a crate standing on the floor
COLOURS = np.array([[0.6, 0.4, 0.2], [0.8, 0.8, 0.7], [0.3, 0.5, 0.8], [0.9, 0.9, 0.9], [0.8, 0.2, 0.2]])


def look_at(pos: np.ndarray, target: np.ndarray) -> np.ndarray:
    """OpenCV camera-to-world at ``pos`` looking at ``target`` (y down)."""
    fwd = (target - pos) / np.linalg.norm(target - pos)
    right = np.cross([0.0, 1.0, 0.0], fwd)
    right /= np.linalg.norm(right)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([right, np.cross(fwd, right), fwd], 1)
    c2w[:3, 3] = pos
    return c2w


def ray_cast(c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Render (H, W, 3) colours and (H, W) labels of the room seen from ``c2w`` (exact intersections)."""
    rays = pixel_rays(torch.tensor(K), torch.tensor(c2w), image_pixels(H, W).double())
    o, d = (t.numpy() for t in rays)  # (H*W, 3) float64
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
    p = o + best_t[:, None] * d
    checker = (np.floor(p[:, 0] * 3) + np.floor(p[:, 1] * 3) + np.floor(p[:, 2] * 3)) % 2
    rgb = COLOURS[label] * (0.75 + 0.25 * checker[:, None])
    return rgb.reshape(H, W, 3), label.reshape(H, W)


def miou(pred: np.ndarray, gt: np.ndarray, n: int) -> float:
    """Mean IoU over classes present in gt, from one hand-made confusion matrix."""
    conf = np.zeros((n, n), dtype=np.int64)
    np.add.at(conf, (gt.ravel(), pred.ravel()), 1)
    inter = np.diag(conf)
    union = conf.sum(0) + conf.sum(1) - inter
    present = conf.sum(1) > 0
    return float((inter[present] / union[present]).mean())


def test_miou_helper_on_a_known_case() -> None:
    gt = np.array([0, 0, 1, 1, 2])
    pred = np.array([0, 1, 1, 1, 0])
    # class 0: inter 1, union 3; class 1: inter 2, union 3; class 2: inter 0, union 1
    assert abs(miou(pred, gt, 3) - (1 / 3 + 2 / 3 + 0) / 3) < 1e-12


@pytest.fixture
def one_thread() -> Iterator[None]:
    """Run on one intra-op thread: hundreds of small steps stall badly on a shared 2-core machine
    when two OpenMP threads wait on each other; restored afterwards."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def test_overfits_a_training_view_of_a_small_scene(one_thread: None) -> None:
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    target = np.array([0.0, 0.2, 3.0])
    positions = [np.array([x, y, 0.0]) for x, y in [(-0.6, -0.2), (0.6, -0.2), (-0.5, 0.3), (0.5, 0.3),
                                                    (0.0, 0.0), (0.15, -0.1)]]
    cams = [look_at(p, target) for p in positions]
    views = [ray_cast(c) for c in cams]
    src_ids, train_ids = [0, 1, 2, 3], [4, 5]
    src_rgb = torch.tensor(np.stack([views[i][0] for i in src_ids]), dtype=torch.float32).permute(0, 3, 1, 2)
    src_K = torch.tensor(K, dtype=torch.float32).expand(4, 3, 3)
    src_c2w = torch.tensor(np.stack([cams[i] for i in src_ids]), dtype=torch.float32)

    cfg = SRayConfig(n_classes=5, n_coarse=8, n_fine=8, n_source=4)
    net = SRayModel(cfg)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: 1.0 - 0.9 * s / STEPS)
    pixels = image_pixels(H, W)
    for step in range(STEPS):
        q = train_ids[step % 2]
        pick = torch.tensor(rng.choice(H * W, 128, replace=False))
        origins, dirs = pixel_rays(torch.tensor(K, dtype=torch.float32),
                                   torch.tensor(cams[q], dtype=torch.float32), pixels[pick])
        src = net.encode(src_rgb, src_K, src_c2w)
        out = net.render_rays(src, origins, dirs, NEAR, FAR, stratified=True)
        label = torch.tensor(views[q][1].reshape(-1)[pick.numpy()])
        rgb = torch.tensor(views[q][0].reshape(-1, 3)[pick.numpy()], dtype=torch.float32)
        loss, _ = render_loss(out, label, rgb, cfg)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()

    net.eval()
    with torch.no_grad():
        src = net.encode(src_rgb, src_K, src_c2w)
        img = net.render_image(src, torch.tensor(K, dtype=torch.float32),
                               torch.tensor(cams[4], dtype=torch.float32), (H, W), NEAR, FAR, chunk=512)
    pred = img["fine"]["logits"].argmax(-1).numpy()
    score = miou(pred, views[4][1], 5)
    assert score > 0.9, f"mIoU {score:.3f} after {STEPS} steps"
