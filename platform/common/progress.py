"""Rank-0 progress that reads cleanly on a terminal, in a log file and in a Ray job's log.

On a terminal a bar redraws in place (tqdm, or Ray's driver-drawn ``tqdm_ray`` in a worker); in a file every
redraw would stay as one more line, so there progress is plain lines. The driver decides from its own standard
output and hands the choice to its Ray workers (whose output is always a file) through :data:`PROGRESS_ENV`.
"""

from __future__ import annotations

import os
import sys
import time
from typing import Any

import ray
from ray.experimental import tqdm_ray
from tqdm import tqdm

PROGRESS_ENV = "SRAY_PROGRESS"
"""Environment variable naming how progress is shown: ``bar`` or ``lines``."""
LINE_EVERY_S = 30.0
"""Seconds between two progress lines (the last step always gets one)."""


class _RayBar:
    """Ray's driver-rendered bar (``ray.experimental.tqdm_ray``): ETA and rate, one line per bar."""

    def __init__(self, total: int, initial: int, desc: str) -> None:
        self.desc = desc
        self._bar = tqdm_ray.tqdm(total=total, desc=desc, unit="step")
        if initial:
            self._bar.update(initial)

    def update(self, n: int = 1) -> None:
        """Advance by ``n`` steps."""
        self._bar.update(n)

    def set_postfix(self, **values: Any) -> None:
        """Show ``key=value`` pairs after the description."""
        self._bar.set_description(f"{self.desc} " + " ".join(f"{k}={v}" for k, v in values.items()))

    def close(self) -> None:
        """Finish the bar."""
        self._bar.close()


class LineProgress:
    """Progress as plain lines: ``[sray] DESC: step N/TOTAL (P%), R s/step, ETA M:SS, key=value ...``,
    at most one every ``every_s`` seconds and always one at the last step."""

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
    if mode in ("bar", "lines"):
        return mode
    return "bar" if sys.stdout.isatty() else "lines"


def progress_env() -> dict[str, str]:
    """``{PROGRESS_ENV: mode}`` of this (driver) process, for its Ray workers' runtime environment."""
    return {PROGRESS_ENV: progress_mode()}


def make_progress(enabled: bool, total: int, initial: int = 0, desc: str = "") -> Any:
    """Progress with ETA when ``enabled`` (rank 0), else a silent bar: :class:`LineProgress` in ``lines`` mode, else
    Ray's driver-drawn bar inside a Ray worker, else tqdm."""
    if not enabled:
        return tqdm(disable=True)
    if progress_mode() == "lines":
        return LineProgress(total, initial, desc)
    if ray.is_initialized() and ray.get_runtime_context().worker.mode == ray.WORKER_MODE:
        return _RayBar(total, initial, desc)
    return tqdm(total=total, initial=initial, desc=desc, unit="step", mininterval=1.0)
