"""The learning-rate schedule under a CPU budget: the warm-up counts steps, the decay follows the step count or
the spent share of the budget, whichever is further along (``budget_lr_factor``), from the end of the warm-up or
from the first ray step (``optim.lr_decay_start``), checked against the formula written out by hand."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sray.platform.config.optim_settings import OptimSettings
from sray.platform.config.train_config import TrainConfig, apply_override, check_sections
from sray.platform.train.state import budget_lr_factor, lr_lambda

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


RAYS = OptimSettings(steps=20000, cpu_seconds=7200.0, lr=1e-3, lr_final=1e-4, warmup_steps=100,
                     warmup_2d_steps=1500, lr_decay_start="rays")


def _rays_by_hand(step: int, cpu: float, ray_cpu: float) -> float:
    if step < 100:
        return (step + 1) / 100
    if step < 1500:
        return 1.0  # the 2D phase trains at the base lr
    ray_share = max((step - 1500) / (20000 - 1500), (cpu - ray_cpu) / (7200 - ray_cpu))
    return 0.1 ** min(1.0, ray_share)


@given(st.integers(0, 30000), st.floats(0.0, 3000.0), st.floats(0.0, 7000.0))
def test_a_decay_started_at_the_ray_phase_spans_its_steps_or_its_share_of_the_budget(step: int, ray_cpu: float,
                                                                                      spent: float) -> None:
    """``lr_decay_start=rays``: the base lr through the 2D warm-up; then the decay follows the ray phase's own
    steps or its own share of the budget left when it began, whichever is further along."""
    cpu = ray_cpu + spent if step >= 1500 else ray_cpu * step / 1500
    assert budget_lr_factor(RAYS, step, cpu, ray_cpu) == pytest.approx(_rays_by_hand(step, cpu, ray_cpu), rel=1e-9)


def test_without_a_budget_the_ray_phase_decay_reaches_lr_final_at_the_cap() -> None:
    factor = lr_lambda(dataclasses.replace(RAYS, cpu_seconds=0.0))
    assert [factor(s) for s in (99, 100, 1499, 1500)] == pytest.approx([1.0, 1.0, 1.0, 1.0])
    assert factor(1500 + (20000 - 1500) // 2) == pytest.approx(math.sqrt(0.1))
    assert factor(20000) == pytest.approx(0.1)
    assert lr_lambda(OPT)(1500) == pytest.approx(0.1 ** (1400 / 19900))  # the whole-run decay, for contrast


def test_a_ray_phase_decay_without_a_2d_warm_up_is_refused_with_the_fix() -> None:
    cfg = TrainConfig()
    cfg.optim.lr_decay_start = "rays"
    with pytest.raises(ValueError, match=r"optim\.lr_decay_start.*optim\.warmup_2d_steps > 0"):
        check_sections(cfg)
    with pytest.raises(ValueError, match="optim.lr_decay_start"):
        apply_override(TrainConfig(), "optim.lr_decay_start=ray")


def test_a_negative_weight_decay_is_refused_with_the_fix() -> None:
    cfg = TrainConfig()
    cfg.optim.weight_decay = -0.1
    with pytest.raises(ValueError, match=r"optim\.weight_decay is -0\.1.*optim\.weight_decay=0\.1"):
        check_sections(cfg)

