"""The time budget of a per-scene training: wall and CPU seconds of its training steps, and which limit ends it.

Both the fleet's finetune (:mod:`sray.platform.finetune.scene_finetune`) and the stability suite's trained-on-scene
points (:mod:`sray.platform.stability.scene_points`) time each training step (data, forward, backward, update;
evaluation is protocol overhead and is left out) with a :class:`StepClock`, and stop at the first limit of
``finetune.max_seconds`` (wall) or ``finetune.max_cpu_seconds`` (CPU) that :func:`time_limit_reached` names.

CPU seconds are ``time.process_time()`` of the training process, every thread of it: unlike wall time they do not
grow when other jobs share the cores, so methods budgeted by CPU seconds compare at equal compute on a busy
machine. The trainings time themselves in their own process and start no loader workers (``num_workers=0``),
so the process's clock holds all of their work.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

from sray.platform.config.fleet_config import FinetuneSettings


class StepClock:
    """Wall and CPU seconds spent inside :meth:`step` blocks so far."""

    def __init__(self) -> None:
        """Start at zero."""
        self.wall_s = 0.0
        self.cpu_s = 0.0

    @contextlib.contextmanager
    def step(self) -> Iterator[None]:
        """Time one training step (its wall and this process's CPU seconds are added when the block ends)."""
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
