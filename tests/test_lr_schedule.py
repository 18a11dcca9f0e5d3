"""The learning-rate schedule under a CPU budget: the warm-up counts steps, the decay follows the step count or
the spent share of the budget, whichever is further along (``budget_lr_factor``), from the end of the warm-up,
checked against the formula written out by hand."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sray.platform.config.train_config import OptimSettings
from sray.platform.train.state import budget_lr_factor

OPT = OptimSettings(steps=20000, cpu_seconds=7200.0, lr=1e-3, lr_final=1e-4, warmup_steps=100)


def _by_hand(step: int, cpu: float) -> float:
    if step < 100:
        return (step + 1) / 100
    progress = max(step / 20000, cpu / 7200)  # share of the run done, by steps or by CPU
    return 0.1 ** min(1.0, (progress * 20000 - 100) / (20000 - 100))


@given(st.integers(0, 30000), st.floats(0.0, 10000.0))
def test_factor_matches_the_formula(step: int, cpu: float) -> None:
    assert budget_lr_factor(OPT, step, cpu) == pytest.approx(_by_hand(step, cpu), rel=1e-9)


def test_warm_up_counts_steps_even_when_the_budget_runs_ahead() -> None:
    """A cap far above the budget must not cut the warm-up short: at step 10 the CPU share is already far
    beyond 100 steps' worth of the cap, yet the factor is 11/100."""
    assert budget_lr_factor(OPT, 10, 720.0) == pytest.approx(0.11)


def test_the_decay_reaches_lr_final_at_the_budget_before_the_cap() -> None:
    assert budget_lr_factor(OPT, 5000, 7200.0) == pytest.approx(0.1)
    assert budget_lr_factor(OPT, 5000, 3600.0) == pytest.approx(math.exp(math.log(0.1) * (9900 / 19900)))
