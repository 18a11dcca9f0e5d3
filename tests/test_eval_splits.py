"""The side-by-side table of ``sray eval --split`` (the command itself: tests/test_eval.py): percent scores, gaps from
the first split, the largest gap as the headline."""

from __future__ import annotations

import pytest

from sray.platform.eval.split_gap import format_splits, split_summary


def _report(miou: float, scenes: int, views: int, wall_s: float) -> dict:
    level = {"miou": miou, "total_acc": 0.9, "class_avg_acc": None}
    return {"scenes": {f"s{i}": {} for i in range(scenes)}, "wall_s": wall_s,
            "mean": {"n_views": views, "dataset_level": level}}


def test_the_summary_reads_percent_gaps_and_the_largest_gap_from_the_reports() -> None:
    summary = split_summary({"in-distribution": _report(0.6, 16, 64, 32.0),
                             "appearance-shift": _report(0.35, 16, 64, 96.0),
                             "geometry-shift": _report(0.5, 16, 64, 64.0)})
    rows = summary["splits"]
    assert rows["in-distribution"]["gap_miou"] == 0.0 and rows["in-distribution"]["rooms"] == 16
    assert rows["appearance-shift"]["miou"] == pytest.approx(35.0)
    assert rows["appearance-shift"]["gap_miou"] == pytest.approx(25.0)
    assert rows["geometry-shift"]["seconds_per_view"] == pytest.approx(1.0)
    assert rows["geometry-shift"]["class_avg_acc"] is None
    assert summary["largest_gap"] == {"split": "appearance-shift", "points": pytest.approx(25.0)}
    text = format_splits(summary)
    assert "+25.0" in text and "largest gap: 25.0 mIoU points (in-distribution -> appearance-shift)" in text
