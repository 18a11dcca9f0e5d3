"""``sray bench speed-accuracy`` bookkeeping on hand-made rows: the Pareto front, the paired table, the chart."""

from __future__ import annotations

from pathlib import Path

import pytest
from fleet_fixtures import one_thread, tiny_checkpoint, tiny_segmenter  # noqa: F401
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: F401
from train_fixtures import tiny_shards  # noqa: F401

from sray.jobs.bench.speed_accuracy import pareto, table
from sray.jobs.bench.speed_accuracy_run import chart
from sray.model.fast_render import FastRender


def _row(name: str, miou: float, s: float, fast: bool = False) -> dict:
    return {"name": name, "method": "sray", "inputs": "rgb", "miou": miou, "psnr": 20.0, "s_per_view": s, "views": 4,
            "setting": {"fast": {"pixel_stride": 4} if fast else None}}


ROWS = [_row("full", 50.0, 40.0), _row("slow and worse", 45.0, 60.0), _row("fast a", 49.5, 1.0, True),
        _row("fast b", 40.0, 0.5, True), _row("dominated", 39.0, 0.8, True)]


def test_pareto_front_keeps_only_undominated_rows_fastest_first() -> None:
    assert [r["name"] for r in pareto(ROWS)] == ["fast b", "fast a", "full"]


def test_pareto_front_reads_the_named_cost_and_score_and_breaks_cost_ties_by_score() -> None:
    points = [{"name": n, "s": s, "score": y} for n, s, y in
              [("cheap bad", 1.0, 10.0), ("cheap good", 1.0, 12.0), ("mid", 2.0, 11.0), ("dear best", 4.0, 20.0),
               ("dear worse", 5.0, 15.0), ("middling", 3.0, 13.0)]]
    assert [r["name"] for r in pareto(points, cost="s", score="score")] == ["cheap good", "middling", "dear best"]


def test_table_reports_paired_differences_and_speed_ups_against_the_first_row() -> None:
    lines = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[1:-1]] for ln in table(ROWS).splitlines()[2:]}
    assert lines["fast a"][3] == "-0.50" and lines["fast a"][7] == "40.0x" and lines["fast a"][8] == "✓"
    assert lines["full"][3] == "+0.00" and lines["dominated"][8] == "" and lines["full"][1] == "RGB"


def test_chart_is_written(tmp_path: Path) -> None:
    png = chart(ROWS, tmp_path / "sa.png", "protocol line")
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_measure_pairs_the_settings_and_the_fast_path_is_lossless(tiny_shards: Path, tiny_checkpoint: Path) -> None:
    """On the tiny checkpoint: the unoptimised and the optimised full renders score the same views alike
    (lossless to fp32 tolerance) and halving the samples changes the render."""
    from sray.jobs.bench.speed_accuracy import Setting, measure
    from sray.model.fast_render import FastRender

    settings = [Setting("reference", n_source=3, impl="reference"), Setting("fast impl", n_source=3),
                Setting("half", n_source=3, sample_scale=0.5),
                Setting("fast s2", n_source=3, fast=FastRender(pixel_stride=2, confidence=0.9)),
                Setting("rgbd", n_source=3, inputs="rgbd"), Setting("rgb again", n_source=3)]
    rows = measure(tiny_checkpoint, tiny_shards, settings, views_per_scene=1, progress=False)
    by = {r["name"]: r for r in rows}
    assert [r["name"] for r in rows] == [s.name for s in settings] and all(r["views"] >= 1 for r in rows)
    assert abs(by["fast impl"]["miou"] - by["reference"]["miou"]) < 1e-6
    assert abs(by["fast impl"]["psnr"] - by["reference"]["psnr"]) < 1e-3
    assert by["half"]["psnr"] != by["fast impl"]["psnr"]
    assert by["rgbd"]["psnr"] != by["fast impl"]["psnr"]  # the sources' depth moved the samples
    assert by["rgb again"]["psnr"] == by["fast impl"]["psnr"]  # and the next setting renders rgb again


def test_a_store_keeps_each_measured_setting_and_a_rerun_measures_only_the_rest(
        tiny_shards: Path, tiny_checkpoint: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Rows measured with a store come back unchanged from a later run, which renders only the settings (or view
    counts) the store does not hold."""
    from sray.jobs.bench import speed_accuracy
    from sray.jobs.bench.speed_accuracy import Setting, measure
    from sray.model.fast_render import FastRender

    a, b = Setting("full", n_source=3), Setting("fast s2", n_source=3, fast=FastRender(pixel_stride=2, confidence=0.9))
    first = measure(tiny_checkpoint, tiny_shards, [a, b], 1, progress=False, store=tmp_path / "rows")
    rendered: list[int] = []
    timed = speed_accuracy.timed_scores

    def counted(*args, **kwargs):
        rendered.append(1)
        return timed(*args, **kwargs)

    monkeypatch.setattr(speed_accuracy, "timed_scores", counted)
    c = Setting("half", n_source=3, sample_scale=0.5)
    again = measure(tiny_checkpoint, tiny_shards, [a, b, c], 1, progress=False, store=tmp_path / "rows")
    assert again[:2] == first and again[2]["name"] == "half" and len(rendered) == 1
    more_views = measure(tiny_checkpoint, tiny_shards, [a], 2, progress=False, store=tmp_path / "rows")
    assert len(rendered) == 2 and more_views[0]["views"] == 2 * first[0]["views"]


def test_full_settings_render_with_the_checkpoints_own_fine_samples(tiny_shards: Path,
                                                                     tiny_checkpoint: Path) -> None:
    """A setting that names no fine-sample choice renders as the checkpoint was trained (as ``sray eval --render
    full`` does); naming the checkpoint's own choice gives the same render, naming the other one another."""
    from sray.jobs.bench.speed_accuracy import Setting, measure
    from sray.platform.checkpoints.model_loading import model_from_checkpoint

    own = model_from_checkpoint(tiny_checkpoint)[0].cfg.fine_samples
    other = {"new": "union", "union": "new"}[own]
    settings = [Setting("own", n_source=3), Setting("named own", n_source=3, fine_samples=own),
                Setting("other", n_source=3, fine_samples=other), Setting("own again", n_source=3)]
    by = {r["name"]: r for r in measure(tiny_checkpoint, tiny_shards, settings, views_per_scene=1, progress=False)}
    assert [by[n]["fine_samples"] for n in ("own", "named own", "other", "own again")] == [own, own, other, own]
    assert by["named own"]["psnr"] == by["own"]["psnr"] == by["own again"]["psnr"]
    assert by["other"]["psnr"] != by["own"]["psnr"]


def test_chosen_settings_keep_their_order_and_unknown_names_are_refused() -> None:
    import pytest

    from sray.jobs.bench.speed_accuracy import (CHOSEN_TABLE, DEFAULT_TABLE, default_settings, select_settings,
                                                table_title)

    assert [s.name for s in select_settings(None)] == [s.name for s in default_settings()]
    assert [s.name for s in select_settings(["fast s8 c0.9", "full"])] == ["fast s8 c0.9", "full"]
    with pytest.raises(ValueError, match="unknown \\['fastest'\\]"):
        select_settings(["full", "fastest"])
    assert table_title(None) == DEFAULT_TABLE and table_title([]) == DEFAULT_TABLE
    assert table_title(["full", "fast s4 c0.9"]) == CHOSEN_TABLE  # one table for chosen sets, replaced by the next


def test_table_names_a_chosen_first_row_as_the_comparison() -> None:
    header = table([_row("full", 50.0, 40.0), _row("fast a", 49.5, 1.0, True)]).splitlines()[0]
    assert "Δ mIoU vs 'full' (points)" in header and "speed-up vs 'full' (CPU s)" in header


def test_measure_with_zero_views_per_scene_scores_every_test_view(tiny_shards: Path, tiny_checkpoint: Path) -> None:
    from sray.data_tools.loader.shard_loader import make_eval_samples
    from sray.jobs.bench.speed_accuracy import Setting, measure
    from sray.model.fast_render import FastRender
    from sray.platform.eval.zero_shot import select_scenes

    names, _ = select_scenes(tiny_shards, None)
    every = sum(len(list(make_eval_samples(tiny_shards, s, split="test", n_source=3))) for s in names)
    [row] = measure(tiny_checkpoint, tiny_shards, [Setting("fast", n_source=3, fast=FastRender(4, 0.9))], 0,
                    progress=False)
    assert row["views"] == every > len(names)


def test_measure_scores_every_class_over_the_rendered_views(tiny_shards: Path, tiny_checkpoint: Path,
                                                           one_thread: None) -> None:
    """With one test scene, the dataset-level mIoU is the mean of the per-class IoUs of the classes present; the
    shares are those of the labelled pixels and equal in every setting (same views)."""
    from sray.jobs.bench.speed_accuracy import Setting, measure

    rows = measure(tiny_checkpoint, tiny_shards, [Setting("fast s4", n_source=3, fast=FastRender(4, 0.9)),
                                                  Setting("fast s8", n_source=3, fast=FastRender(8, 0.9))], 1,
                   progress=False)
    for row in rows:
        present = [v for v in row["class_iou"] if v is not None]
        assert row["miou"] == pytest.approx(sum(present) / len(present))
        assert sum(row["class_share"]) == pytest.approx(1.0) and len(row["class_names"]) == len(row["class_iou"])
    assert rows[0]["class_share"] == rows[1]["class_share"]


def test_the_command_over_two_checkpoints_applies_the_rule_to_each_and_to_their_mean(
        tiny_shards: Path, tiny_checkpoint: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        one_thread: None) -> None:
    """Both checkpoints' rows, their mean and the rule's verdicts go into the stored table of the section."""
    import json
    from unittest.mock import MagicMock

    from sray.jobs.bench import speed_accuracy_run
    from sray.jobs.bench.speed_accuracy import Setting

    settings = [Setting("full", n_source=3), Setting("fast s8 c0.9", n_source=3, fast=FastRender())]
    monkeypatch.setattr(speed_accuracy_run, "select_settings", lambda names: settings)
    monkeypatch.setattr(speed_accuracy_run, "get_tracker", lambda *args: MagicMock())
    doc = tmp_path / "docs" / "benchmarks.md"
    section = speed_accuracy_run.run_speed_accuracy([tiny_checkpoint, tiny_checkpoint], tiny_shards, 1, doc,
                                                    "mlflow", "")
    assert "IoU per class" in section and "Default render by the rule" in section
    [stored] = json.loads((doc.parent / "benchmarks/speed-accuracy/cpu-only/tables.json").read_text())["tables"]
    tables = [b for b in stored["blocks"] if "header" in b]
    assert [t["header"][0] for t in tables] == ["setting or method", "IoU % (Δ vs first row, points)", "checkpoint"]
    assert tables[0]["header"][-1] == "default rule"
    verdicts = tables[2]["rows"]
    assert [r[0] for r in verdicts] == ["fleet-checkpoint/step_000000000"] * 2 + ["mean of 2"]
    assert all("sray eval (fast s8 c0.9)" in r[3] and "validation, fleet held-out: not measured" in r[3]
               for r in verdicts)
    assert "Checkpoints" in stored["notes"] and "mean over them" in stored["notes"]


def test_paired_settings_add_sray_s_row_of_a_methods_inputs_and_the_twin_is_the_last_naming_them() -> None:
    from sray.jobs.bench.speed_accuracy import Setting, paired_settings, twin

    rgb = [Setting("full", n_source=3), Setting("fast", n_source=3, fast=FastRender())]
    added = paired_settings(rgb, ["rgbd", "rgbd"])
    assert added == [*rgb, Setting("full, rgbd", n_source=3, inputs="rgbd")]  # the first setting's sources
    both = [*rgb, Setting("rgbd a", inputs="rgbd"), Setting("rgbd b", inputs="rgbd", sample_scale=0.5)]
    assert paired_settings(both, ["rgbd"]) == both and twin(both, "rgbd").name == "rgbd b"
    with pytest.raises(ValueError, match="no setting renders S-Ray with inputs 'rgbd'"):
        twin(rgb, "rgbd")


def test_a_2d_transfer_row_is_timed_beside_sray_rgbd_on_the_same_views_and_scores_as_sray_eval(
        tiny_shards: Path, tiny_checkpoint: Path, tiny_segmenter: Path, mlflow_uri: str, tmp_path: Path,
        one_thread: None) -> None:
    """The 2d-transfer row comes right after S-Ray's RGB-D row (added, with the first setting's sources), has its own
    CPU and wall time per view, is scored on the same views (same pixel shares) and its mIoU is `sray eval --method
    2d-transfer`'s on them."""
    import json

    from sray.jobs.bench.speed_accuracy import Setting, measure, paired_settings
    from sray.jobs.bench.speed_methods import method_models
    from sray.jobs.cli import main

    others = method_models(["2d-transfer"], tiny_checkpoint, tiny_segmenter)
    settings = paired_settings([Setting("fast s8", n_source=3, fast=FastRender(8, 0.9))],
                               [m.inputs for m in others.values()])
    rows = measure(tiny_checkpoint, tiny_shards, settings, 0, progress=False, others=others)
    assert [(r["name"], r["method"], r["inputs"]) for r in rows] == [
        ("fast s8", "sray", "rgb"), ("full, rgbd", "sray", "rgbd"), ("2d-transfer", "2d-transfer", "rgbd")]
    sray_rgbd, transfer = rows[1], rows[2]
    assert transfer["setting"] is None and transfer["views"] == sray_rgbd["views"] > 1
    assert transfer["class_share"] == sray_rgbd["class_share"]  # the same labelled pixels
    assert 0 < transfer["s_per_view"] != sray_rgbd["s_per_view"] and transfer["wall_s_per_view"] > 0

    out = tmp_path / "eval"
    assert main(["eval", "--method", "2d-transfer", "--segmenter", str(tiny_segmenter), "--data", str(tiny_shards),
                 "--n-source", "3", "--out", str(out), "--tracking-uri", mlflow_uri]) == 0
    report = json.loads((out / "metrics.json").read_text())
    assert transfer["miou"] == pytest.approx(100 * report["mean"]["dataset_level"]["miou"], abs=1e-9)
    assert transfer["miou"] != pytest.approx(sray_rgbd["miou"])


def test_the_command_lists_the_method_beside_sray_rgbd_and_refuses_what_cannot_be_built(
        tiny_shards: Path, tiny_checkpoint: Path, tiny_segmenter: Path, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], one_thread: None) -> None:
    """With ``--methods 2d-transfer --segmenter S`` the stored table holds S-Ray's added RGB-D row and the method's
    row after it, marked RGB-D and never judged by the rule; a method without its flag, a flag no chosen method
    reads, or a model of another label space exits 2 naming it before anything is measured."""
    import json
    from unittest.mock import MagicMock

    from sray.jobs.bench import speed_accuracy_run
    from sray.jobs.bench.speed_accuracy import Setting
    from sray.jobs.cli import main
    from sray.platform.eval.segmenter import Segmenter, SegmenterConfig, save_segmenter

    monkeypatch.setattr(speed_accuracy_run, "select_settings", lambda names: [Setting("full", n_source=3)])
    monkeypatch.setattr(speed_accuracy_run, "get_tracker", lambda *args: MagicMock())
    doc = tmp_path / "docs" / "benchmarks.md"
    speed_accuracy_run.run_speed_accuracy([tiny_checkpoint], tiny_shards, 1, doc, "mlflow", "",
                                          methods=["2d-transfer"], segmenter=tiny_segmenter)
    [stored] = json.loads((doc.parent / "benchmarks/speed-accuracy/cpu-only/tables.json").read_text())["tables"]
    main_table = next(b for b in stored["blocks"] if "header" in b)
    assert main_table["header"][:2] == ["setting or method", "inputs"]
    assert [(r[0], r[1], r[-1]) for r in main_table["rows"]] == [
        ("full", "RGB", "**chosen**"), ("full, rgbd", "RGB-D", "not offered"),
        ("2d-transfer", "RGB-D", "another method")]
    assert "'2d-transfer' (RGB-D, built from `--segmenter`)" in stored["notes"]

    base = ["bench", "speed-accuracy", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards),
            "--doc", str(tmp_path / "other.md")]
    assert main([*base, "--methods", "2d-transfer"]) == 2
    assert "pass --segmenter FOLDER" in capsys.readouterr().err
    assert main([*base, "--segmenter", str(tiny_segmenter)]) == 2
    assert "--segmenter does not apply to --methods (none)" in capsys.readouterr().err
    wrong = save_segmenter(Segmenter(SegmenterConfig(n_classes=3)), {}, tmp_path / "three-classes")
    assert main([*base, "--methods", "2d-transfer", "--segmenter", str(wrong)]) == 2
    assert "method 2d-transfer: the segmenter predicts 3 classes" in capsys.readouterr().err
    assert not (tmp_path / "other.md").exists()
