"""``sray bench speed-accuracy`` bookkeeping on hand-made rows: the Pareto front, the paired table, the chart."""

from __future__ import annotations

from pathlib import Path

from fleet_fixtures import tiny_checkpoint  # noqa: F401
from train_fixtures import tiny_shards  # noqa: F401

from sray.jobs.bench.speed_accuracy import chart, pareto, table


def _row(name: str, miou: float, s: float, fast: bool = False) -> dict:
    return {"name": name, "miou": miou, "psnr": 20.0, "s_per_view": s, "views": 4,
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
    assert lines["fast a"][2] == "-0.50" and lines["fast a"][6] == "40.0x" and lines["fast a"][7] == "✓"
    assert lines["full"][2] == "+0.00" and lines["dominated"][7] == ""


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
