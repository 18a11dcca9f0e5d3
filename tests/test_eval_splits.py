"""``sray eval --split``: zero-shot scores on several splits side by side with the gap from the first split;
``--calibrate``: the fast rule's temperature fitted on validation rooms and used for every split."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: E402,F401  (pytest fixtures, used by name)
from test_eval import tiny_checkpoint  # noqa: E402,F401
from train_fixtures import tiny_shards  # noqa: E402,F401

from sray.platform.eval.split_gap import format_splits, split_summary  # noqa: E402


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


def test_eval_scores_each_split_and_the_same_data_has_no_gap(tiny_checkpoint, tiny_shards, mlflow_uri, tmp_path,
                                                             capsys) -> None:
    from sray.jobs.cli import main

    out = tmp_path / "eval"
    args = ["eval", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--n-source", "3",
            "--stride", "4", "--out", str(out), "--tracking-uri", mlflow_uri]
    assert main([*args, "--split", "again"]) == 2 and "NAME=DIR" in capsys.readouterr().err
    assert main([*args, "--split", f"again={tiny_shards}", "--calibrate", str(tiny_shards)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "splits.json").read_text())
    main_report = json.loads((out / "metrics.json").read_text())
    again = json.loads((out / "again" / "metrics.json").read_text())
    assert summary["splits"]["again"]["miou"] == pytest.approx(100 * again["mean"]["dataset_level"]["miou"])
    assert summary["splits"]["again"]["miou"] == pytest.approx(100 * main_report["mean"]["dataset_level"]["miou"])
    assert summary["splits"]["again"]["gap_miou"] == pytest.approx(0.0, abs=1e-9)
    assert "largest gap: 0.0 mIoU points (data -> again)" in printed
    calibration = json.loads((out / "calibration.json").read_text())
    assert calibration["rays"] > 0 and calibration["nll_fitted"] <= calibration["nll_at_1"] + 1e-9
    for report in (main_report, again):  # both splits scored with the fitted temperature
        assert f"at temperature {calibration['temperature']:.3g}" in report["protocol"]["render"]
