"""``sray lab accuracy --step-times``: each variant's timed step is its cells' training step, variants with the
same step are timed once, the Pareto front against hand-picked points, and the table column and chart."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch
from test_lab_accuracy import PLAN3, TOY, _cell

from sray.lab.accuracy import cells as accuracy_cells
from sray.lab.accuracy.plan import LONG, Cell
from sray.lab.accuracy.step_cost import (
    measure_step_times,
    read_step_times,
    step_spec,
    store_step_times,
)
from sray.jobs.bench.workloads import model_config
from sray.lab.accuracy.tables import accuracy_bench, write_tables
from sray.platform.common.bench_doc import bench_dir

CPU = torch.device("cpu")


@pytest.mark.parametrize("variant", ["full", "none", "full-new", "full-rgbd", LONG])
def test_the_timed_step_is_the_cells_training_step(tmp_path: Path, variant: str) -> None:
    """The spec's model is exactly the cell's model section, at its batch size and the world's image size."""
    cfg = accuracy_cells.cell_config(Cell(variant, 0), TOY, tmp_path / "shards", tmp_path, "sqlite:///x.db")
    spec = step_spec(variant, TOY, CPU)
    assert model_config(spec) == cfg.model
    assert spec["rays"] == cfg.data.rays_per_batch == 32 and spec["hw"] == (36, 48) and spec["dtype"] == "fp32"


def test_the_timed_step_runs_in_the_recipes_precision() -> None:
    bf16 = dataclasses.replace(TOY, overrides=(*TOY.overrides, "run.precision=bf16"))
    assert step_spec("full", bf16, CPU)["dtype"] == "bf16"


@pytest.mark.slow
def test_variants_with_the_same_step_are_timed_once_and_rgbd_steps_run(tmp_path: Path) -> None:
    times = measure_step_times(TOY, [LONG, "full", "full-rgbd"], CPU, rounds=1)
    assert times["full"]["same_step_as"] == LONG and times["full"]["runs"] == times[LONG]["runs"]
    assert times["full-rgbd"]["same_step_as"] == "full-rgbd"
    assert all(t["s_per_step"] > 0 and t["peak_rss_gib"] > 0 and t["rays"] == 32 for t in times.values())
    store_step_times(tmp_path, times, "test machine")
    assert read_step_times(tmp_path) == {"machine": "test machine", "variants": times}
    assert read_step_times(tmp_path / "elsewhere") is None


def test_tables_show_each_variants_step_time_and_chart_it(tmp_path: Path) -> None:
    doc = tmp_path / "docs" / "benchmarks.md"
    stored = {"full-s0": _cell("full", 0, 0.4), "full-s1": _cell("full", 1, 0.5), "none-s0": _cell("none", 0, 0.3)}
    timed = {"variants": {"full": {"s_per_step": 1.25, "rays": 32}, "none": {"s_per_step": 0.5, "rays": 32}},
             "machine": "test machine"}
    write_tables("toy", PLAN3, stored, tmp_path / "no-fleet", doc, timed)
    text = doc.read_text()
    rows = {line.split(" | ")[0]: line for line in text.splitlines() if " | " in line}
    assert rows["variant"].endswith("| eval min | s / step (side by side)")
    assert rows["full"].startswith("full | 2 | 2/3 | 45.00 ± 7.07") and rows["full"].endswith("| 1.250")
    assert rows["none"].endswith("| 0.500")
    assert "test machine" in text and "zero_shot_vs_step_time.png" in text
    assert (bench_dir(doc, accuracy_bench("toy")) / "zero_shot_vs_step_time.png").stat().st_size > 0
    write_tables("toy", PLAN3, stored, tmp_path / "no-fleet", tmp_path / "plain.md")
    assert "s / step" not in (tmp_path / "plain.md").read_text()
