"""Live throughput of a training loop: rays per second, the share of the step spent waiting for data, peak memory."""

from __future__ import annotations

import resource
import sys
import time
from collections.abc import Iterator
from typing import TypeVar

import torch

T = TypeVar("T")


def peak_memory_mb(device: torch.device) -> float:
    """Peak memory of this process in MiB: the CUDA allocator's on a GPU, else the peak resident set size
    (``ru_maxrss``: KiB on Linux, bytes on macOS)."""
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated(device) / 2**20
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10


class ThroughputWindow:
    """Throughput over the steps since the last :meth:`report`; batches come through :meth:`next_batch` (timed as
    data wait) and each step ends with :meth:`step_done`."""

    def __init__(self, rays_per_batch: int, world_size: int, device: torch.device) -> None:
        """Count ``rays_per_batch`` rays per step on each of ``world_size`` ranks; memory is read on ``device``."""
        self.rays_per_batch, self.world_size, self.device = rays_per_batch, world_size, device
        self._open()

    def _open(self) -> None:
        self.start, self.steps, self.wait_s = time.perf_counter(), 0, 0.0

    def next_batch(self, batches: Iterator[T]) -> T:
        """``next(batches)``, its waiting time counted as data wait."""
        start = time.perf_counter()
        batch = next(batches)
        self.wait_s += time.perf_counter() - start
        return batch

    def step_done(self) -> None:
        """Count one finished step."""
        self.steps += 1

    def report(self) -> dict[str, float]:
        """``rays_per_s`` (rays per batch x ranks x steps / wall seconds), ``data_wait_share`` (of the wall seconds)
        and ``memory_mb`` (the peak so far) of this window; the next window starts now."""
        elapsed = max(time.perf_counter() - self.start, 1e-9)
        figures = {"rays_per_s": self.rays_per_batch * self.world_size * self.steps / elapsed,
                   "data_wait_share": self.wait_s / elapsed, "memory_mb": peak_memory_mb(self.device)}
        self._open()
        return figures


def progress_postfix(loss: float, figures: dict[str, float]) -> dict[str, str]:
    """The ``key=value`` pairs of a progress line: loss, rays/s, data-wait share and peak memory."""
    return {"loss": f"{loss:.3f}", "rays/s": f"{figures['rays_per_s']:.0f}",
            "data_wait": f"{100 * figures['data_wait_share']:.0f}%", "peak_mem": f"{figures['memory_mb']:.0f}MiB"}
