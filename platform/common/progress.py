"""Rank-0 progress: a bar on a terminal, plain lines in a file, where every redraw would stay as one more line (the
driver decides and tells its Ray workers by :data:`PROGRESS_ENV`), with a training loop's live throughput."""

from __future__ import annotations

import os
import resource
import sys
import time
from collections.abc import Iterator
from typing import Any, TypeVar

import ray
import torch
from ray.experimental import tqdm_ray
from tqdm import tqdm

PROGRESS_ENV = "SRAY_PROGRESS"
"""Environment variable naming how progress is shown: ``bar`` or ``lines``."""
LINE_EVERY_S = 30.0
T = TypeVar("T")


class _RayBar(tqdm_ray.tqdm):
    """Ray's driver-rendered bar (``tqdm_ray``: ETA and rate, one line per bar), with tqdm's ``set_postfix``."""

    def __init__(self, total: int, initial: int, desc: str) -> None:
        super().__init__(total=total, desc=desc, unit="step")
        self.desc = desc
        if initial:
            self.update(initial)

    def set_postfix(self, **values: Any) -> None:
        """Show ``key=value`` pairs after the description."""
        self.set_description(f"{self.desc} " + " ".join(f"{k}={v}" for k, v in values.items()))


class LineProgress:
    """``[sray] DESC: step N/TOTAL (P%), R s/step, ETA M:SS, key=value ...``: one per ``every_s`` s, and the last."""

    def __init__(self, total: int, initial: int = 0, desc: str = "", every_s: float = LINE_EVERY_S) -> None:
        self.total, self.n, self.desc, self.every_s = total, initial, desc, every_s
        self._start_n, self._start = initial, time.monotonic()
        self._last, self._shown_n, self._postfix = self._start, initial, ""

    def update(self, n: int = 1) -> None:
        """Advance by ``n`` steps; print a line when ``every_s`` has passed or the last step is done."""
        self.n += n
        now = time.monotonic()
        if now - self._last >= self.every_s or self.n >= self.total:
            self._emit(now)

    def set_postfix(self, **values: Any) -> None:
        """``key=value`` pairs shown at the end of the next line."""
        self._postfix = " ".join(f"{k}={v}" for k, v in values.items())

    def close(self) -> None:
        """Print the final position if the last line did not show it."""
        if self.n != self._shown_n:
            self._emit(time.monotonic())

    def _emit(self, now: float) -> None:
        done, elapsed = self.n - self._start_n, now - self._start
        parts = [f"step {self.n}/{self.total} ({100 * self.n / max(self.total, 1):.0f}%)"]
        if done > 0:
            per_step = elapsed / done
            eta = int(round(per_step * max(self.total - self.n, 0)))
            parts.append(f"{per_step:.2f} s/step, ETA {eta // 60}:{eta % 60:02d}")
        if self._postfix:
            parts.append(self._postfix)
        print(f"[sray] {self.desc}: " + ", ".join(parts), flush=True)
        self._last, self._shown_n = now, self.n


def progress_mode() -> str:
    """``bar`` or ``lines``: :data:`PROGRESS_ENV` when set, else ``bar`` only if standard output is a terminal."""
    mode = os.environ.get(PROGRESS_ENV, "")
    return mode if mode in ("bar", "lines") else "bar" if sys.stdout.isatty() else "lines"


def progress_env() -> dict[str, str]:
    """``{PROGRESS_ENV: mode}`` of this (driver) process, for its Ray workers' runtime environment."""
    return {PROGRESS_ENV: progress_mode()}


def make_progress(enabled: bool, total: int, initial: int = 0, desc: str = "") -> Any:
    """Progress with ETA when ``enabled`` (rank 0): lines, Ray's bar in a Ray worker, else tqdm; else a silent bar."""
    if not enabled:
        return tqdm(disable=True)
    if progress_mode() == "lines":
        return LineProgress(total, initial, desc)
    if ray.is_initialized() and ray.get_runtime_context().worker.mode == ray.WORKER_MODE:
        return _RayBar(total, initial, desc)
    return tqdm(total=total, initial=initial, desc=desc, unit="step", mininterval=1.0)


def peak_memory_mb(device: torch.device) -> float:
    """Peak memory of this process in MiB: the CUDA allocator's on a GPU, else the peak resident set size."""
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated(device) / 2**20
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10


class ThroughputWindow:
    """Throughput over the steps since the last :meth:`report` (batches through :meth:`next_batch`)."""

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
        """``rays_per_s`` (of all ranks), ``data_wait_share`` and peak ``memory_mb`` of this window; opens the next."""
        elapsed = max(time.perf_counter() - self.start, 1e-9)
        figures = {"rays_per_s": self.rays_per_batch * self.world_size * self.steps / elapsed,
                   "data_wait_share": self.wait_s / elapsed, "memory_mb": peak_memory_mb(self.device)}
        self._open()
        return figures


def progress_postfix(loss: float, figures: dict[str, float]) -> dict[str, str]:
    """The ``key=value`` pairs of a progress line: loss, rays/s, data-wait share and peak memory."""
    return {"loss": f"{loss:.3f}", "rays/s": f"{figures['rays_per_s']:.0f}",
            "data_wait": f"{100 * figures['data_wait_share']:.0f}%", "peak_mem": f"{figures['memory_mb']:.0f}MiB"}
