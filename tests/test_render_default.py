"""The default-render rule (``sray.jobs.bench.render_default``) on hand-made rows, and the renders used today."""

from __future__ import annotations

import pytest

from sray.jobs.bench.render_default import (
    MAX_CLASS_LOSS,
    MAX_MIOU_LOSS,
    MIN_CLASS_SHARE,
    Measured,
    choose_default,
    todays_defaults,
)
from sray.model.fast_render import FastRender

SHARE = {"wall": 0.6, "floor": 0.3, "chair": 0.095, "lamp": 0.005}
"""Shares of the labelled test pixels: lamp holds under 1%."""


def _row(name: str, seconds: float, miou: float = 50.0, **iou: float) -> Measured:
    """A measured setting: every class at the reference's IoU unless named."""
    base = {"wall": 80.0, "floor": 70.0, "chair": 30.0, "lamp": 20.0}
    return Measured(name, miou, seconds, base | iou, dict(SHARE))


FULL = _row("full", 40.0)


def test_the_thresholds_are_the_issues() -> None:
    assert (MAX_MIOU_LOSS, MAX_CLASS_LOSS, MIN_CLASS_SHARE) == (1.0, 3.0, 0.01)


def test_a_setting_within_the_overall_limit_but_losing_a_counted_class_is_rejected() -> None:
    rows = [FULL, _row("fast s8", 0.3, miou=49.5, chair=26.5), _row("fast s4", 1.0, miou=49.8, chair=28.0)]
    choice = choose_default(rows, "full")
    assert choice.chosen == "fast s4"
    [why] = choice.rejected()["fast s8"]
    assert (why.where, why.loss, why.limit) == ("chair", pytest.approx(3.5), MAX_CLASS_LOSS)
    assert why.describe() == "chair -3.50" and list(choice.rejected()) == ["fast s8"]


def test_an_overall_loss_over_one_point_rejects_and_every_shortfall_is_named() -> None:
    rows = [FULL, _row("fast s8", 0.3, miou=48.9, wall=70.0, floor=66.0)]
    choice = choose_default(rows, "full")
    assert choice.chosen == "full"
    assert [s.describe() for s in choice.rejected()["fast s8"]] == ["overall -1.10", "wall -10.00", "floor -4.00"]


def test_limits_are_inclusive() -> None:
    rows = [FULL, _row("edge", 1.0, miou=49.0, chair=27.0)]  # exactly 1 point overall, exactly 3 on chair
    assert choose_default(rows, "full").chosen == "edge"


def test_a_class_under_one_percent_of_the_pixels_is_not_counted() -> None:
    rows = [FULL, _row("fast s8", 0.3, lamp=0.0)]  # lamp: 0.5% of the pixels, 20 points lost
    choice = choose_default(rows, "full")
    assert choice.chosen == "fast s8" and choice.counted == ("wall", "floor", "chair")


def test_ties_in_time_go_to_the_higher_miou_then_to_the_first_listed() -> None:
    rows = [FULL, _row("b", 1.0, miou=49.5), _row("a", 1.0, miou=49.9), _row("c", 1.0, miou=49.9)]
    choice = choose_default(rows, "full")
    assert choice.chosen == "a" and list(choice.shortfalls) == ["a", "c", "b", "full"]


def test_the_full_render_always_qualifies() -> None:
    rows = [_row("fast", 0.1, miou=30.0), FULL, _row("fast too", 1.0, floor=10.0)]
    choice = choose_default(rows, "full")
    assert choice.chosen == "full" and choice.passes("full") and not choice.passes("fast")
    assert list(choice.rejected()) == ["fast", "fast too"]
    assert choose_default([FULL], "full").chosen == "full"


def test_bad_rows_are_refused_with_the_names() -> None:
    with pytest.raises(ValueError, match="reference 'full render' is not among the rows"):
        choose_default([FULL], "full render")
    with pytest.raises(ValueError, match="setting 'other views'.*class 'chair'"):
        choose_default([FULL, _row("other views", 1.0, chair=None)], "full")


def test_todays_defaults_are_what_sray_eval_validation_and_the_fleet_render() -> None:
    """``sray eval``'s own defaults are ``FastRender()``; validation and the fleet render every scored pixel."""
    from sray.jobs.cli import build_parser

    args = build_parser().parse_args(["eval", "--checkpoint", "c", "--data", "d"])
    today = todays_defaults()
    assert args.render == "fast" and today["sray eval"] == FastRender(args.fast_stride, args.fast_confidence)
    assert today["validation"] == today["fleet held-out"] == FastRender(pixel_stride=1, confidence=0.9)
