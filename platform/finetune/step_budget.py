"""The time budget of a per-scene training: wall and CPU seconds of its training steps (not of evaluation)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

from sray.platform.config.fleet_config import FinetuneSettings


class StepClock:
    """Wall and CPU seconds spent inside :meth:`step` blocks so far."""

    def __init__(self) -> None:
        self.wall_s, self.cpu_s = 0.0, 0.0

    @contextlib.contextmanager
    def step(self) -> Iterator[None]:
        """Add the block's wall and this process's CPU seconds."""
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self.wall_s += time.perf_counter() - wall
            self.cpu_s += time.process_time() - cpu


def time_limit_reached(settings: FinetuneSettings, clock: StepClock) -> str | None:
    """``"max_seconds"`` or ``"max_cpu_seconds"`` when that budget (> 0) is spent, else None (wall first)."""
    if 0 < settings.max_seconds <= clock.wall_s:
        return "max_seconds"
    if 0 < settings.max_cpu_seconds <= clock.cpu_s:
        return "max_cpu_seconds"
    return None
