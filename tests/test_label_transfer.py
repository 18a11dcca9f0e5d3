"""Label transfer against independent references: analytic visibility on a scene with an occluder, a naive
splatting loop, OpenCV's projection, the identity, and a coverage counted by hand."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from sray.platform.eval.label_transfer import UNSEEN, project_points, transfer_labels

WALL_Z, CARD_Z, CARD_HALF = 4.0, 2.0, 0.3
"""The toy scene: a wall (plane z = 4) and a square card (z = 2, |x|, |y| <= 0.3) in front of it."""
LEFT, RIGHT, CARD, IGNORE = 1, 2, 3, 255


def camera(eye: tuple[float, float, float], yaw: float = 0.0) -> np.ndarray:
    """(4, 4) c2w at ``eye`` looking along +z turned by ``yaw`` radians about the y axis (OpenCV axes)."""
    c, s = np.cos(yaw), np.sin(yaw)
    c2w = np.eye(4)
    c2w[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    c2w[:3, 3] = eye
    return c2w


def intrinsics(h: int, w: int, f: float) -> np.ndarray:
    """(3, 3) K with a centred principal point."""
    return np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])


def render(K: np.ndarray, c2w: np.ndarray, h: int, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Analytic z-depth (H, W), labels (H, W) and world points (H, W, 3) of the toy scene."""
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T @ c2w[:3, :3].T  # camera z = 1
    eye = c2w[:3, 3]
    t_card = (CARD_Z - eye[2]) / rays[..., 2]
    on_card = eye + t_card[..., None] * rays
    hits = (t_card > 0) & (np.abs(on_card[..., 0]) <= CARD_HALF) & (np.abs(on_card[..., 1]) <= CARD_HALF)
    t = np.where(hits, t_card, (WALL_Z - eye[2]) / rays[..., 2])
    points = eye + t[..., None] * rays
    label = np.where(points[..., 0] < 0, LEFT, RIGHT)
    label[points[..., 1] < -0.8] = IGNORE
    label[hits] = CARD
    return t, label, points


def sees(eye: np.ndarray, K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int], point: np.ndarray) -> bool:
    """Analytic visibility: the point projects inside the source image and the segment from the source
    centre to it does not cross the card first."""
    cam = np.linalg.inv(c2w) @ np.append(point, 1.0)
    u, v = (K @ cam[:3])[:2] / cam[2]
    if cam[2] <= 0 or not (-0.5 <= u < hw[1] - 0.5 and -0.5 <= v < hw[0] - 0.5):
        return False
    s = (CARD_Z - eye[2]) / (point[2] - eye[2])
    crossing = eye + s * (point - eye)
    return not (0 < s < 1 - 1e-9 and abs(crossing[0]) <= CARD_HALF and abs(crossing[1]) <= CARD_HALF)


def tensors(*arrays: np.ndarray) -> list[torch.Tensor]:
    """float32 tensors of numpy arrays (the loader's dtype)."""
    return [torch.from_numpy(np.asarray(a, np.float32)) for a in arrays]


H, W = 36, 48
K_TOY = intrinsics(H, W, 40.0)
QUERY = camera((0.0, 0.0, 0.0))
SOURCE = camera((0.7, 0.1, 0.0), yaw=-0.1)


def test_backward_transfer_reproduces_visible_labels_and_hides_occluded_pixels() -> None:
    """Oracle transfer of ground-truth labels from a source beside the query: every pixel the analytic test
    calls visible gets its own label, every hidden pixel (behind the card from the source, or outside the
    source's frame) is UNSEEN; the few disagreements sit on a silhouette of the analytic visibility."""
    q_depth, q_label, q_points = render(K_TOY, QUERY, H, W)
    s_depth, s_label, _ = render(K_TOY, SOURCE, H, W)
    k_src, c2w_src, s_d, k_q, c2w_q, q_d = tensors(K_TOY[None], SOURCE[None], s_depth[None], K_TOY, QUERY, q_depth)
    out = transfer_labels(torch.from_numpy(s_label[None]), k_src, c2w_src, s_d, k_q, c2w_q, (H, W), "backward",
                          query_depth=q_d, ignore_id=IGNORE)
    visible = np.array([[sees(SOURCE[:3, 3], K_TOY, SOURCE, (H, W), q_points[v, u]) for u in range(W)]
                        for v in range(H)])
    expected = np.where(visible, q_label, UNSEEN)
    expected[visible & (q_label == IGNORE)] = UNSEEN  # unlabelled source pixels cast no vote
    wrong = (out.labels.numpy() != expected) & (q_label != IGNORE)
    assert (~visible & (q_label != IGNORE)).sum() > 40, "the toy scene must hide some labelled pixels"
    edge = np.zeros_like(visible)
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            edge |= np.roll(visible, (dv, du), (0, 1)) != visible
            edge |= np.roll(q_label, (dv, du), (0, 1)) != q_label
    assert wrong.sum() <= 0.02 * wrong.size and not (wrong & ~edge).any(), np.argwhere(wrong & ~edge)
    assert (out.seen.numpy() == visible)[~edge].all()


def test_backward_transfer_without_source_depth_carries_what_each_source_pixel_shows() -> None:
    """The RGB protocol's transfer (no source depth, so no occlusion test), against OpenCV's projection: every query
    point in front of the source and inside its frame takes the label of the source pixel it projects to, the
    source pixels nearest to ``cv2.projectPoints``'s coordinates, occluded or not: the wall behind the card, hidden
    from the source, is labelled card."""
    q_depth, q_label, q_points = render(K_TOY, QUERY, H, W)
    _, s_label, _ = render(K_TOY, SOURCE, H, W)
    k_src, c2w_src, k_q, c2w_q, q_d = tensors(K_TOY[None], SOURCE[None], K_TOY, QUERY, q_depth)
    out = transfer_labels(torch.from_numpy(s_label[None]), k_src, c2w_src, None, k_q, c2w_q, (H, W), "backward",
                          query_depth=q_d, ignore_id=IGNORE)
    w2c = np.linalg.inv(SOURCE)
    uv, _ = cv2.projectPoints(q_points.reshape(-1, 3), cv2.Rodrigues(w2c[:3, :3])[0], w2c[:3, 3], K_TOY, None)
    iu, iv = (np.floor(uv[:, 0, i] + 0.5).astype(int).reshape(H, W) for i in (0, 1))
    inside = (iu >= 0) & (iu < W) & (iv >= 0) & (iv < H)  # every query point lies in front of the source here
    seen_label = np.where(inside, s_label[iv.clip(0, H - 1), iu.clip(0, W - 1)], IGNORE)
    expected = np.where(inside & (seen_label != IGNORE), seen_label, UNSEEN)
    np.testing.assert_array_equal(out.seen.numpy(), inside)
    np.testing.assert_array_equal(out.labels.numpy(), expected)
    hidden = np.array([[inside[v, u] and not sees(SOURCE[:3, 3], K_TOY, SOURCE, (H, W), q_points[v, u])
                        for u in range(W)] for v in range(H)])
    assert (hidden & (q_label != CARD) & (out.labels.numpy() == CARD)).sum() > 20, "no occlusion test: card wins"
    with pytest.raises(ValueError, match="forward splatting needs the source depth"):
        transfer_labels(torch.from_numpy(s_label[None]), k_src, c2w_src, None, k_q, c2w_q, (H, W), "forward")


def naive_splat(labels: np.ndarray, K: np.ndarray, c2w: np.ndarray, depth: np.ndarray, K_q: np.ndarray,
                c2w_q: np.ndarray, hw: tuple[int, int], tol: float, ignore: int) -> np.ndarray:
    """Forward splatting written as plain loops over sources and pixels (the module doc's rules)."""
    m, h, w = depth.shape
    w2c_q = np.linalg.inv(c2w_q)
    best = np.full((m, *hw), np.inf)
    label = np.full((m, *hw), UNSEEN)
    for j in range(m):
        for v in range(h):
            for u in range(w):
                d = depth[j, v, u]
                if d <= 0:
                    continue
                world = c2w[j] @ np.append(d * np.linalg.inv(K[j]) @ [u, v, 1.0], 1.0)
                cam = (w2c_q @ world)[:3]
                if cam[2] <= 0:
                    continue
                pu, pv = (K_q @ cam)[:2] / cam[2]
                iu, iv = int(np.floor(pu + 0.5)), int(np.floor(pv + 0.5))
                if 0 <= iu < hw[1] and 0 <= iv < hw[0] and cam[2] < best[j, iv, iu]:
                    best[j, iv, iu], label[j, iv, iu] = cam[2], labels[j, v, u]
    out = np.full(hw, UNSEEN)
    for v in range(hw[0]):
        for u in range(hw[1]):
            front = best[:, v, u].min()
            votes = [label[j, v, u] for j in range(m)
                     if np.isfinite(best[j, v, u]) and abs(best[j, v, u] - front) < tol * front
                     and label[j, v, u] != ignore]
            if votes:
                counts = {c: votes.count(c) for c in votes}
                top = max(counts.values())
                out[v, u] = next(c for c in votes if counts[c] == top)  # votes are in source order
    return out


def test_forward_splatting_agrees_with_a_naive_loop() -> None:
    """Two sources (one sees behind the card, one from the other side) splatted into the query: the vectorised
    z-buffer and vote equal the per-pixel loop exactly, and never read the query's depth."""
    h, w = 18, 24
    K = intrinsics(h, w, 20.0)
    cams = [camera((0.7, 0.1, 0.0), yaw=-0.1), camera((-0.5, -0.2, 0.3), yaw=0.15)]
    renders = [render(K, c, h, w) for c in cams]
    depth = np.stack([r[0] for r in renders])
    labels = np.stack([r[1] for r in renders])
    labels[1, :, ::3] = LEFT  # disagreeing votes: ties and majorities both occur
    Ks, c2ws = np.stack([K, K]), np.stack(cams)
    out = transfer_labels(torch.from_numpy(labels), *tensors(Ks, c2ws, depth, K, QUERY), (h, w), "forward",
                          ignore_id=IGNORE)
    reference = naive_splat(labels, Ks, c2ws, depth.astype(np.float32).astype(np.float64), K, QUERY, (h, w), 0.05,
                            IGNORE)
    assert (reference != UNSEEN).sum() > h * w // 2
    np.testing.assert_array_equal(out.labels.numpy(), reference)
    with pytest.raises(ValueError, match="must not read"):
        transfer_labels(torch.from_numpy(labels), *tensors(Ks, c2ws, depth, K, QUERY), (h, w), "forward",
                        query_depth=torch.ones(h, w))


@pytest.mark.parametrize("mode", ["backward", "forward"])
def test_identical_cameras_transfer_the_identity(mode: str) -> None:
    """Source = query camera and depth: each labelled pixel keeps its own label (unlabelled ones get none)."""
    depth, label, _ = render(K_TOY, SOURCE, H, W)
    k, c2w, d = tensors(K_TOY, SOURCE, depth)
    out = transfer_labels(torch.from_numpy(label[None]), k[None], c2w[None], d[None], k, c2w, (H, W), mode,
                          query_depth=d if mode == "backward" else None, ignore_id=IGNORE)
    np.testing.assert_array_equal(out.labels.numpy(), np.where(label == IGNORE, UNSEEN, label))
    assert bool(out.seen.all())


def test_projection_matches_opencv() -> None:
    """``project_points`` against ``cv2.projectPoints`` (rotation vector and translation of world-to-camera)."""
    rng = np.random.default_rng(0)
    points = rng.uniform([-1, -1, 2], [1, 1, 5], size=(50, 3))
    cams = [camera((0.3, -0.2, 0.1), yaw=0.2), camera((-0.4, 0.1, -0.3), yaw=-0.3)]
    K = np.stack([intrinsics(240, 320, 277.0), intrinsics(120, 160, 140.0)])
    uv, z = project_points(torch.from_numpy(points), torch.from_numpy(K), torch.from_numpy(np.stack(cams)))
    for j, c2w in enumerate(cams):
        w2c = np.linalg.inv(c2w)
        expected, _ = cv2.projectPoints(points, cv2.Rodrigues(w2c[:3, :3])[0], w2c[:3, 3], K[j], None)
        np.testing.assert_allclose(uv[j].numpy(), expected[:, 0], atol=1e-9)
        np.testing.assert_allclose(z[j].numpy(), points @ w2c[2, :3] + w2c[2, 3], atol=1e-12)


@pytest.mark.parametrize("mode", ["backward", "forward"])
def test_coverage_equals_a_hand_count(mode: str) -> None:
    """A wall 1 m in front of both cameras (f = 10 px), the source 0.2 m to the right: every point moves 2
    pixels left, so query columns 0 and 1 fall outside the source. Row 0 is unlabelled: 6 of 8 columns of the
    3 labelled rows are covered, 18 of 24 labelled pixels."""
    h, w = 4, 8
    K = intrinsics(h, w, 10.0)
    src = camera((0.2, 0.0, 0.0))
    depth = np.ones((h, w))
    label = np.full((h, w), LEFT)
    label[0] = IGNORE
    k, c2w_s, c2w_q, d = tensors(K, src, QUERY, depth)
    out = transfer_labels(torch.from_numpy(label[None]), k[None], c2w_s[None], d[None], k, c2w_q, (h, w), mode,
                          query_depth=d if mode == "backward" else None, ignore_id=IGNORE)
    labelled = torch.from_numpy(label) != IGNORE
    assert (int((out.seen & labelled).sum()), int(labelled.sum())) == (18, 24)
    assert not out.seen[:, :2].any() and bool(out.seen[:, 2:].all())
