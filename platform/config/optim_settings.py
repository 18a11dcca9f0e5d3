"""The optimiser section of a training config: schedule, budget, stability guards and what the weights keep."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class OptimSettings:
    """Optimiser, schedule and stability guards."""

    steps: int = 250_000
    """Total optimiser steps (paper: 250k)."""
    lr: float = 1e-3
    """Initial Adam learning rate (paper: 1e-3)."""
    lr_final: float = 5e-5
    """Learning rate reached at the last step by exponential decay (paper: 5e-5)."""
    warmup_steps: int = 0
    """Linear warm-up steps before the decay starts."""
    grad_clip: float = 1.0
    """Global gradient-norm clipping threshold (0 disables clipping)."""
    cpu_seconds: float = 0.0
    """Stop once the job has spent this many CPU seconds, summed over its ranks and their loader processes
    (``sray.platform.train.cpu_clock``), or at ``steps``, whichever comes first; the learning-rate decay then
    follows the larger of the step and the CPU fraction (set ``steps`` as a cap). 0 = steps only."""
    warmup_2d_steps: int = 0
    """The first this many steps train the encoder and its source-view head on the source views' labels
    alone (nothing rendered; a departure from the paper, docs/model.md); they count toward ``steps``. Needs
    ``model.lambda_src_sem`` > 0; 0 = off."""
    max_nonfinite_in_row: int = 20
    """A non-finite loss or gradient skips the step; this many in a row stop the job."""
