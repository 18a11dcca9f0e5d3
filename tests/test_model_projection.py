"""Rays, projection and feature gathering of sray.model, checked against OpenCV and numpy."""

from __future__ import annotations

import cv2
import numpy as np
import torch

from sray.model.encoder import FEATURE_STRIDE
from sray.model.rays import image_pixels, pixel_rays
from sray.model.reprojection import project, sample_maps, valid_projection, view_direction_difference
from sray.model.source_set import rigid_inverse


def _random_camera(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random pinhole K (3, 3) and a random rigid c2w (4, 4), float64."""
    w, h = rng.integers(40, 400, size=2)
    K = np.array([[rng.uniform(30, 500), 0.0, rng.uniform(0, w)],
                  [0.0, rng.uniform(30, 500), rng.uniform(0, h)],
                  [0.0, 0.0, 1.0]])
    rot, _ = cv2.Rodrigues(rng.normal(size=3) * 1.5)
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = rot, rng.normal(size=3) * 3
    return K, c2w


def test_project_agrees_with_opencv_project_points() -> None:
    rng = np.random.default_rng(0)
    cams = [_random_camera(rng) for _ in range(5)]
    points = rng.normal(size=(200, 3)) * 4
    K = torch.tensor(np.stack([k for k, _ in cams]))
    w2c = rigid_inverse(torch.tensor(np.stack([c for _, c in cams])))
    uv, depth = project(torch.tensor(points), K, w2c)
    for i, (k, c2w) in enumerate(cams):
        w2c_np = np.linalg.inv(c2w)
        front = (points @ w2c_np[:3, :3].T + w2c_np[:3, 3])[:, 2] > 0.1
        rvec, _ = cv2.Rodrigues(w2c_np[:3, :3])
        ref, _ = cv2.projectPoints(points[front], rvec, w2c_np[:3, 3], k, None)
        torch.testing.assert_close(uv[i][torch.tensor(front)], torch.tensor(ref[:, 0, :]), rtol=0, atol=1e-4)
        cam_z = (points @ w2c_np[:3, :3].T + w2c_np[:3, 3])[:, 2]
        torch.testing.assert_close(depth[i], torch.tensor(cam_z), rtol=0, atol=1e-9)


def test_pixel_rays_reach_their_pixel_at_z_depth_t() -> None:
    rng = np.random.default_rng(1)
    K, c2w = _random_camera(rng)
    uv = torch.tensor(rng.uniform(0, 300, size=(64, 2)))
    origins, dirs = pixel_rays(torch.tensor(K), torch.tensor(c2w), uv)
    t = torch.tensor(rng.uniform(0.3, 20, size=(64, 1)))
    uv_back, depth = project(origins + t * dirs, torch.tensor(K)[None], rigid_inverse(torch.tensor(c2w))[None])
    torch.testing.assert_close(uv_back[0], uv, rtol=0, atol=1e-8)
    torch.testing.assert_close(depth[0], t[:, 0], rtol=0, atol=1e-10)
    torch.testing.assert_close(origins, torch.tensor(c2w[:3, 3]).expand(64, 3))


def test_image_pixels_are_row_major_centres() -> None:
    uv = image_pixels(3, 4)
    assert uv.shape == (12, 2)
    assert uv[5].tolist() == [1.0, 1.0] and uv[11].tolist() == [3.0, 2.0]


def _bilinear_numpy(feat: np.ndarray, x: float, y: float) -> np.ndarray:
    """Explicit 4-neighbour interpolation of feat (C, h, w) at map coordinates (x, y), border clamp."""
    h, w = feat.shape[1:]
    x, y = min(max(x, 0.0), w - 1.0), min(max(y, 0.0), h - 1.0)
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    x1, y1 = min(x0 + 1, w - 1), min(y0 + 1, h - 1)
    ax, ay = x - x0, y - y0
    return ((1 - ax) * (1 - ay) * feat[:, y0, x0] + ax * (1 - ay) * feat[:, y0, x1]
            + (1 - ax) * ay * feat[:, y1, x0] + ax * ay * feat[:, y1, x1])


def test_gathered_features_equal_direct_bilinear_sampling() -> None:
    rng = np.random.default_rng(2)
    H, W = 48, 64
    h, w = -(-H // FEATURE_STRIDE), -(-W // FEATURE_STRIDE)
    cams = []
    for _ in range(3):
        K = np.array([[50.0, 0, (W - 1) / 2], [0, 50.0, (H - 1) / 2], [0, 0, 1]])
        rot, _ = cv2.Rodrigues(rng.normal(size=3) * 0.1)
        c2w = np.eye(4)
        c2w[:3, :3], c2w[:3, 3] = rot, rng.normal(size=3) * 0.2
        cams.append((K, c2w))
    feats = rng.normal(size=(3, 5, h, w)).astype(np.float32)
    z = rng.uniform(1, 5, size=(40, 1))
    points = np.concatenate([z * rng.uniform(-0.7, 0.7, size=(40, 2)), z], 1).reshape(4, 10, 3)  # (R, N, 3)
    K = torch.tensor(np.stack([k for k, _ in cams]), dtype=torch.float32)
    w2c = rigid_inverse(torch.tensor(np.stack([c for _, c in cams]), dtype=torch.float32))
    uv, depth = project(torch.tensor(points, dtype=torch.float32), K, w2c)
    got = sample_maps(torch.tensor(feats), uv, FEATURE_STRIDE)  # (m, C, R, N)
    valid = valid_projection(uv, depth, (H, W), 1e-3)
    assert valid.float().mean() > 0.3, "test rig should see a good share of its points"
    for i, (k, c2w) in enumerate(cams):
        w2c_np = np.linalg.inv(c2w)
        rvec, _ = cv2.Rodrigues(w2c_np[:3, :3])
        ref_uv, _ = cv2.projectPoints(points.reshape(-1, 3), rvec, w2c_np[:3, 3], k, None)
        for p, (u, v) in enumerate(ref_uv[:, 0, :]):
            r, n = divmod(p, 10)
            if not valid[i, r, n]:
                continue
            expected = _bilinear_numpy(feats[i], u / FEATURE_STRIDE, v / FEATURE_STRIDE)
            expected_t = torch.tensor(expected, dtype=torch.float32)
            torch.testing.assert_close(got[i, :, r, n], expected_t, rtol=0, atol=2e-4)


def test_feature_pixel_centres_sit_on_every_fourth_full_res_pixel() -> None:
    feats = torch.randn(2, 3, 6, 7)
    j = torch.arange(7).repeat(6)
    i = torch.arange(6).repeat_interleave(7)
    uv = torch.stack([FEATURE_STRIDE * j, FEATURE_STRIDE * i], -1).float()  # (42, 2)
    got = sample_maps(feats, uv[None, :, None, :].expand(2, 42, 1, 2), FEATURE_STRIDE)[..., 0]
    torch.testing.assert_close(got, feats[:, :, i, j], rtol=0, atol=1e-6)


def test_validity_requires_inside_image_and_in_front() -> None:
    uv = torch.tensor([[[-0.4, 0.0], [-0.6, 0.0], [9.5, 4.5], [9.6, 1.0], [3.0, 3.0]]])
    depth = torch.tensor([[1.0, 1.0, 1.0, 1.0, -2.0]])
    assert valid_projection(uv, depth, (5, 10), 1e-3).tolist() == [[True, False, True, False, False]]


def test_view_direction_difference_matches_its_definition() -> None:
    rng = np.random.default_rng(3)
    points = rng.normal(size=(2, 3, 3)) + np.array([0, 0, 5.0])
    qdir = rng.normal(size=(2, 3))
    centres = rng.normal(size=(4, 3))
    got = view_direction_difference(torch.tensor(points), torch.tensor(qdir), torch.tensor(centres))
    for i in range(4):
        for r in range(2):
            for n in range(3):
                q = qdir[r] / np.linalg.norm(qdir[r])
                s = points[r, n] - centres[i]
                s = s / np.linalg.norm(s)
                diff = (q - s) / np.linalg.norm(q - s)
                torch.testing.assert_close(got[i, r, n], torch.tensor(np.append(diff, q @ s)))
