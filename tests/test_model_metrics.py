"""Segmentation and colour metrics against hand-computed numbers and naive references."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from sray.model.metrics import (
    DATASET_PROTOCOL,
    LPIPS_NOTE,
    PER_IMAGE_PROTOCOL,
    confusion_matrix,
    per_image_miou,
    psnr,
    scene_metrics,
)
from sray.model.ssim import SSIM_K1, SSIM_K2, ssim

IGNORE = 255
N_CLASSES = 5  # ground truth holds {0, 1, 2}; 3 is only predicted; 4 appears nowhere

# Two 2x4 images. Ignored pixels carry predictions (2 and 4, then 1) that must never count.
TARGET_A = torch.tensor([[0, 0, 0, 0], [1, 1, IGNORE, IGNORE]])
PRED_A = torch.tensor([[0, 0, 0, 3], [1, 0, 2, 4]])
TARGET_B = torch.tensor([[2, 2, 2, 1], [1, 1, 0, IGNORE]])
PRED_B = torch.tensor([[2, 2, 3, 1], [1, 2, 0, 1]])


def test_confusion_matrix_of_the_hand_made_scene() -> None:
    conf = confusion_matrix(torch.stack([PRED_A, PRED_B]), torch.stack([TARGET_A, TARGET_B]),
                            N_CLASSES, IGNORE)
    expected = torch.zeros(5, 5, dtype=torch.int64)
    for (gt, pr), count in {(0, 0): 4, (0, 3): 1, (1, 0): 1, (1, 1): 3, (1, 2): 1,
                            (2, 2): 2, (2, 3): 1}.items():
        expected[gt, pr] = count
    torch.testing.assert_close(conf, expected, atol=0, rtol=0)
    assert int(conf.sum()) == 13  # 16 pixels, 3 ignored


def test_dataset_level_protocol_counts_only_ground_truth_classes() -> None:
    conf = confusion_matrix(PRED_A, TARGET_A, N_CLASSES, IGNORE) + confusion_matrix(
        PRED_B, TARGET_B, N_CLASSES, IGNORE)
    m = scene_metrics(conf)
    # IoU_c = TP / (TP + FP + FN): class 0: 4 / (5 + 5 - 4); class 1: 3 / (5 + 3 - 3);
    # class 2: 2 / (3 + 3 - 2). Class 3 (predicted only) and class 4 (nowhere) are not averaged.
    iou = [4 / 6, 3 / 5, 2 / 4]
    assert math.isclose(m["miou"], sum(iou) / 3, rel_tol=1e-12)
    assert math.isclose(m["total_acc"], 9 / 13, rel_tol=1e-12)
    assert math.isclose(m["class_avg_acc"], (4 / 5 + 3 / 5 + 2 / 3) / 3, rel_tol=1e-12)
    assert m["n_classes_present"] == 3 and m["n_pixels"] == 13
    assert all(math.isnan(v) for v in m["iou_per_class"][3:])
    assert m["protocol"] == DATASET_PROTOCOL


def test_per_image_protocol_differs_from_dataset_level() -> None:
    m = per_image_miou([PRED_A, PRED_B], [TARGET_A, TARGET_B], N_CLASSES, IGNORE)
    # Image A (classes 0, 1): IoU0 = 3 / (4 + 4 - 3), IoU1 = 1 / (2 + 1 - 1).
    # Image B (classes 0, 1, 2): IoU0 = 1 / 1, IoU1 = 2 / (3 + 2 - 2), IoU2 = 2 / (3 + 3 - 2).
    miou_a, miou_b = (3 / 5 + 1 / 2) / 2, (1 + 2 / 3 + 1 / 2) / 3
    assert math.isclose(m["miou"], (miou_a + miou_b) / 2, rel_tol=1e-12)
    assert math.isclose(m["total_acc"], (4 / 6 + 5 / 7) / 2, rel_tol=1e-12)
    assert math.isclose(m["class_avg_acc"], ((3 / 4 + 1 / 2) / 2 + (1 + 2 / 3 + 2 / 3) / 3) / 2,
                        rel_tol=1e-12)
    assert m["protocol"] == PER_IMAGE_PROTOCOL and m["n_images"] == 2
    assert not math.isclose(m["miou"], (4 / 6 + 3 / 5 + 2 / 4) / 3, rel_tol=1e-3)


def test_unlabelled_images_are_skipped_and_counted() -> None:
    empty = torch.full((2, 4), IGNORE)
    m = per_image_miou(torch.stack([PRED_A, PRED_A]), torch.stack([TARGET_A, empty]),
                       N_CLASSES, IGNORE)
    assert m["n_images"] == 1 and m["n_images_skipped"] == 1
    assert math.isclose(m["miou"], (3 / 5 + 1 / 2) / 2, rel_tol=1e-12)
    assert math.isnan(scene_metrics(torch.zeros(3, 3, dtype=torch.int64))["miou"])


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 6), st.integers(0, 200), st.integers(0, 10_000))
def test_confusion_matrix_matches_a_loop(n_classes: int, n_pixels: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    pred = rng.integers(0, n_classes, n_pixels)
    target = np.where(rng.random(n_pixels) < 0.2, IGNORE, rng.integers(0, n_classes, n_pixels))
    expected = np.zeros((n_classes, n_classes), dtype=np.int64)
    for p, t in zip(pred, target, strict=True):
        if t != IGNORE:
            expected[t, p] += 1
    conf = confusion_matrix(torch.from_numpy(pred), torch.from_numpy(target), n_classes, IGNORE)
    torch.testing.assert_close(conf, torch.from_numpy(expected), atol=0, rtol=0)


def test_out_of_range_ids_raise() -> None:
    with pytest.raises(ValueError, match="`pred` holds ids outside"):
        confusion_matrix(torch.tensor([0, 5]), torch.tensor([0, 1]), 5, IGNORE)
    with pytest.raises(ValueError, match="`target` holds ids outside"):
        confusion_matrix(torch.tensor([0, 1]), torch.tensor([0, 9]), 5, IGNORE)
    with pytest.raises(ValueError, match="argmax"):
        confusion_matrix(torch.rand(4), torch.tensor([0, 1, 1, 0]), 5, IGNORE)


def test_psnr_of_a_constant_error() -> None:
    g = torch.Generator().manual_seed(0)
    img = torch.rand(6, 7, 3, generator=g, dtype=torch.float64) * 0.8
    assert math.isclose(psnr(img + 0.1, img), 20.0, abs_tol=1e-6)
    assert math.isclose(psnr(img + 0.01, img), 40.0, abs_tol=1e-6)


def _naive_ssim(x: np.ndarray, y: np.ndarray) -> float:
    """SSIM by explicit loops over every fully-inside 11x11 window and every channel."""
    coords = np.arange(11) - 5.0
    g = np.exp(-(coords**2) / (2 * 1.5**2))
    w = np.outer(g, g) / np.outer(g, g).sum()
    c1, c2 = (SSIM_K1 * 1.0) ** 2, (SSIM_K2 * 1.0) ** 2
    values = []
    for c in range(x.shape[2]):
        for i in range(x.shape[0] - 10):
            for j in range(x.shape[1] - 10):
                a, b = x[i:i + 11, j:j + 11, c], y[i:i + 11, j:j + 11, c]
                mx, my = (w * a).sum(), (w * b).sum()
                vx, vy = (w * (a - mx) ** 2).sum(), (w * (b - my) ** 2).sum()
                cov = (w * (a - mx) * (b - my)).sum()
                values.append((2 * mx * my + c1) * (2 * cov + c2)
                              / ((mx**2 + my**2 + c1) * (vx + vy + c2)))
    return float(np.mean(values))


def test_ssim_matches_a_naive_window_loop() -> None:
    rng = np.random.default_rng(1)
    x = rng.random((15, 14, 3))
    y = np.clip(x + 0.2 * rng.standard_normal(x.shape), 0, 1)
    got = ssim(torch.from_numpy(y), torch.from_numpy(x))
    assert math.isclose(got, _naive_ssim(y, x), rel_tol=1e-9)
    assert got < 0.95


def test_ssim_properties() -> None:
    g = torch.Generator().manual_seed(2)
    x = torch.rand(2, 16, 18, 3, generator=g)
    y = (x + 0.1 * torch.randn(x.shape, generator=g)).clamp(0, 1)
    assert math.isclose(ssim(x, x), 1.0, rel_tol=1e-12)
    assert math.isclose(ssim(x, y), ssim(y, x), rel_tol=1e-12)
    noisier = (x + 0.3 * torch.randn(x.shape, generator=g)).clamp(0, 1)
    assert ssim(x, noisier) < ssim(x, y) < 1.0
    # Constant images: variances and covariance vanish, leaving the luminance term.
    a, b = 0.3, 0.7
    c1 = SSIM_K1**2
    expected = (2 * a * b + c1) / (a**2 + b**2 + c1)
    got = ssim(torch.full((12, 12), a), torch.full((12, 12), b))
    assert math.isclose(got, expected, rel_tol=1e-6)
    with pytest.raises(ValueError, match="at least 11x11"):
        ssim(torch.rand(8, 20), torch.rand(8, 20))


def test_lpips_note_explains_its_absence() -> None:
    assert "LPIPS" in LPIPS_NOTE and "download" in LPIPS_NOTE
