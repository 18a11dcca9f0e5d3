"""Live throughput figures of a training loop checked on values: rays/s, data-wait share, peak memory."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import torch

from sray.platform.common.progress import ThroughputWindow, peak_memory_mb, progress_postfix


def _slow_batches(wait_s: float) -> Iterator[int]:
    """A loader whose every batch takes ``wait_s`` seconds to arrive."""
    n = 0
    while True:
        time.sleep(wait_s)
        yield n
        n += 1


def test_rays_per_second_is_rays_times_ranks_over_seconds_per_step() -> None:
    """4 steps of a known duration on 3 ranks of 256 rays: rays/s = 256 x 3 / (seconds per step)."""
    window = ThroughputWindow(rays_per_batch=256, world_size=3, device=torch.device("cpu"))
    start = time.perf_counter()
    for _ in range(4):
        time.sleep(0.05)
        window.step_done()
    figures = window.report()
    per_step = (time.perf_counter() - start) / 4
    assert abs(figures["rays_per_s"] - 256 * 3 / per_step) < 0.05 * figures["rays_per_s"]


def test_data_wait_share_exceeds_half_when_the_loader_sleeps() -> None:
    """A loader sleeping 60 ms per batch beside 10 ms of compute: most of the window is data wait; with no wait
    the share is near 0; a report opens a fresh window."""
    window = ThroughputWindow(rays_per_batch=64, world_size=1, device=torch.device("cpu"))
    batches = _slow_batches(0.06)
    for _ in range(4):
        window.next_batch(batches)
        time.sleep(0.01)
        window.step_done()
    assert window.report()["data_wait_share"] > 0.5
    fast = iter(range(10))
    for _ in range(4):
        window.next_batch(fast)
        time.sleep(0.01)
        window.step_done()
    assert window.report()["data_wait_share"] < 0.2


def test_peak_memory_is_at_least_a_tensor_allocated_on_purpose() -> None:
    """After touching a 200 MiB array the process's peak resident set is at least that large."""
    block = np.ones(200 * 2**20 // 8)  # 200 MiB of float64, every page written
    assert block.sum() > 0
    assert peak_memory_mb(torch.device("cpu")) >= 200
    figures = ThroughputWindow(8, 1, torch.device("cpu")).report()
    postfix = progress_postfix(1.23456, figures)
    assert postfix["loss"] == "1.235" and postfix["peak_mem"].endswith("MiB") and postfix["data_wait"].endswith("%")
