"""Class-frequency-aware loss: pixel counts, weights and the weighted cross-entropy against naive references."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scene_fixtures
import torch
from loss_settings import LossConfig

from sray.data_tools.loader.class_stats import balanced_weights, count_pixels, dataset_pixel_counts
from sray.data_tools.scene import IGNORE_ID
from sray.jobs.data.command import format_stats
from sray.model.losses import render_loss


def test_pixel_counts_match_a_per_pixel_loop() -> None:
    rng = np.random.default_rng(0)
    labels = [np.where(rng.random((7, 9)) < 0.2, IGNORE_ID, rng.integers(0, 5, (7, 9))).astype(np.uint16)
              for _ in range(3)]
    expected = np.zeros(6, np.int64)
    for label in labels:
        for value in label.ravel().tolist():
            expected[5 if value == IGNORE_ID else value] += 1
    assert count_pixels(labels, 5).tolist() == expected.tolist()
    with pytest.raises(ValueError, match="outside"):
        count_pixels([np.array([[7]], np.uint16)], 5)


def test_dataset_counts_and_the_stats_table(tmp_path: Path) -> None:
    root = scene_fixtures.write_dataset(tmp_path / "d", [("a", 4, "train"), ("b", 4, "test")])
    names, per_scene = dataset_pixel_counts(root)
    assert sorted(per_scene) == ["a", "b"] and all(c.sum() == 4 * 30 * 40 for c in per_scene.values())
    table = format_stats(names, per_scene)
    assert table.splitlines()[-1] == f"2 scenes, {2 * 4 * 30 * 40} pixels"
    shares = [float(line.split()[-2]) for line in table.splitlines()[1:len(names) + 1]]
    assert sum(shares) == pytest.approx(100.0, abs=0.05)


def test_balanced_weights_by_hand() -> None:
    counts = np.array([81, 9, 0, 1])
    w = np.array(balanced_weights(counts, "inverse-sqrt", max_ratio=100))
    raw = np.array([1 / 9, 1 / 3, 1.0, 1.0])            # f^-1/2 with f = counts / 91 (up to a common factor)
    raw = raw / np.sum(counts / 91 * raw)
    np.testing.assert_allclose(w, raw, rtol=1e-12)
    assert np.sum(counts / 91 * w) == pytest.approx(1.0)
    clipped = np.array(balanced_weights(counts, "inverse", max_ratio=10))
    assert clipped[3] / clipped[0] == pytest.approx(10.0) and clipped[2] == clipped.max()
    assert balanced_weights(counts, "none") == [1.0] * 4


def test_weighted_cross_entropy_against_a_loop() -> None:
    gen = torch.Generator().manual_seed(0)
    logits = torch.randn(12, 4, generator=gen)
    target = torch.tensor([0, 1, 2, 3, IGNORE_ID, 1, 1, 0, IGNORE_ID, 3, 2, 2])
    weights = (0.5, 2.0, 1.0, 3.0)
    out = {"coarse": {"logits": logits, "rgb": torch.zeros(12, 3)}}
    loss, terms = render_loss(out, target, torch.zeros(12, 3), LossConfig(class_weights=weights))
    num = den = 0.0
    for i in range(12):
        if int(target[i]) != IGNORE_ID:
            ce = -torch.log_softmax(logits[i], 0)[target[i]]
            num, den = num + weights[int(target[i])] * float(ce), den + weights[int(target[i])]
    torch.testing.assert_close(terms["sem_coarse"], torch.tensor(num / den), rtol=1e-6, atol=1e-6)
    unweighted, _ = render_loss(out, target, torch.zeros(12, 3), LossConfig())
    equal, _ = render_loss(out, target, torch.zeros(12, 3), LossConfig(class_weights=(2.0,) * 4))
    torch.testing.assert_close(equal, unweighted, rtol=1e-6, atol=1e-6)
    nothing = torch.full((12,), IGNORE_ID)
    logits.requires_grad_(True)
    empty, _ = render_loss(out, nothing, torch.zeros(12, 3), LossConfig(class_weights=weights))
    empty.backward()
    assert float(empty.detach()) == 0.0 and torch.count_nonzero(logits.grad) == 0
