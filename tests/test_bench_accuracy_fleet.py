"""``sray bench accuracy``'s fleet comparison takes its methods from the registry: which methods are compared (a fake
registered method appears, 2d-transfer only with a segmenter), a stored fleet runs again only for the methods it
lacks, the equal-budget table's columns and inputs, and records stored before these changes (an old-harness cell,
old fleet results, a ``done.json`` without methods, the table under its former title) still load."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from sray.jobs.bench import accuracy_fleet
from sray.jobs.bench.accuracy_budgets import BUDGET_TABLE, FORMER_TITLES, budget_table, step_zero
from sray.jobs.bench.accuracy_cells import import_old_cells, stored_cells
from sray.jobs.bench.accuracy_fleet import DONE_FILE, compared_methods, fleet_config, methods_done, run_comparison
from sray.jobs.bench.accuracy_plan import HOUR_INTRA_UNCAPPED, LONG, PRESETS, Cell, Preset, World, headline_variant
from sray.jobs.bench.accuracy_tables import accuracy_bench, write_tables
from sray.jobs.bench.doc import bench_dir, record
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.eval.segmenter import Segmenter, SegmenterConfig, save_segmenter
from sray.platform.finetune.methods.method import ChartStyle, Method
from sray.platform.finetune.methods.registry import METHODS

PRESET = Preset(world=World(train_scenes=1, test_scenes=1, views=20, height=36, width=48), recipe="synth-cpu-hour",
                overrides=(), long_steps=4, ablation_steps=2, validations=1, ckpt_every=2, plan=(Cell(LONG, 0),),
                eval_sources=2, eval_fast=None, budget_s=3.0, budgets=(1.0, 3.0), fleet_eval_stride=4,
                fleet_gpus_per_task=0.0)


def _never(*args: object) -> None:
    raise AssertionError("a test double's builder was called")


def _fake(name: str, check: object = None) -> Method:
    """A registered method that trains per scene (test double; never built here)."""
    return Method(name=name, summary="test double", build=_never, artifact_file="fake.bin", load=_never,
                  style=ChartStyle(label=f"{name} label", color="#000000", marker="o"), uses_sources=False,
                  checked_config=check)


def _refuse(cfg: object) -> object:
    raise ValueError("fleet config: fake.setting is empty; pass --fake")


def _result(scene: str, method: str, curve: list[tuple[float, float]], inputs: str | None) -> dict:
    """A fleet result.json as fleets wrote it before this change (``protocol`` absent when ``inputs`` is None)."""
    protocol = None if inputs is None else EvalProtocol("frustum-overlap v2", 2, 4, inputs=inputs).to_json()
    result = {"scene": scene, "method": method, "status": "finished", "error": None, "steps_used": 9,
              "curve": [{"step": i, "wall_s": w, "miou": m} for i, (w, m) in enumerate(curve)]}
    return result | ({"protocol": protocol} if protocol else {})


def _store(fleet: Path, result: dict) -> None:
    path = fleet / "scenes" / result["scene"] / result["method"] / "result.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result))


def test_the_compared_methods_follow_the_registry(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every registered method whose check accepts the config is compared, in registry order; 2d-transfer and a
    method whose requirement is missing are left out with the reason, until a segmenter is given; a given segmenter
    folder that does not load stops the benchmark."""
    monkeypatch.setitem(METHODS, "fake", _fake("fake"))
    monkeypatch.setitem(METHODS, "fake-needy", _fake("fake-needy", _refuse))
    cfg, compared, left_out = compared_methods(fleet_config(PRESET))
    assert compared == ["sray", "semantic-nerf", "fake"]
    assert list(left_out) == ["2d-transfer", "fake-needy"] and "transfer.segmenter is empty" in left_out["2d-transfer"]
    assert left_out["fake-needy"] == "fleet config: fake.setting is empty; pass --fake"
    assert (cfg.finetune.max_seconds, cfg.finetune.held_out.n_source) == (PRESET.budget_s, PRESET.eval_sources)

    segmenter = save_segmenter(Segmenter(SegmenterConfig(n_classes=3)), {}, tmp_path / "segmenter")
    cfg, compared, _ = compared_methods(fleet_config(PRESET, segmenter))
    assert compared == ["sray", "semantic-nerf", "sray-rgbd", "2d-transfer", "fake"]  # S-Ray given depth beside it
    assert cfg.transfer.segmenter == str(segmenter.resolve())
    with pytest.raises(FileNotFoundError, match="nowhere/segmenter.json: missing"):
        compared_methods(fleet_config(PRESET, tmp_path / "nowhere"))


def test_a_finished_fleet_runs_again_only_for_methods_it_lacks(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """A ``done.json`` written before it named methods counts its stored results' methods; adding 2d-transfer runs
    the fleet with every compared method (its finished pairs are skipped inside) and records them all."""
    fleet, calls = tmp_path / "fleet", []
    for method in ("sray", "semantic-nerf"):
        _store(fleet, _result("s0", method, [(0.0, 0.2)], None))
    (fleet / DONE_FILE).write_text(json.dumps({"checkpoint": "ckpt"}) + "\n")  # an old marker
    monkeypatch.setattr(accuracy_fleet, "run_fleet", lambda *args: calls.append(args[-1]) or [])
    monkeypatch.setattr(accuracy_fleet, "write_fleet_charts", lambda *args: [])
    cfg = fleet_config(PRESET)
    assert methods_done(fleet) == {"sray", "semantic-nerf"} and methods_done(tmp_path / "none") is None
    assert not run_comparison(cfg, ["sray", "semantic-nerf"], Path("ckpt"), tmp_path, ["s0"], fleet, "") and not calls
    three = ["sray", "semantic-nerf", "2d-transfer"]
    assert run_comparison(cfg, three, Path("ckpt"), tmp_path, ["s0"], fleet, "") and calls == [three]
    assert json.loads((fleet / DONE_FILE).read_text())["methods"] == three
    assert not run_comparison(cfg, ["sray"], Path("ckpt"), tmp_path, ["s0"], fleet, "") and len(calls) == 1
    with pytest.raises(ValueError, match=r"fleet/done.json: checkpoint: this fleet finetuned from ckpt, not from "
                                         r"other/ckpt; move .*fleet away"):
        run_comparison(cfg, three, Path("other/ckpt"), tmp_path, ["s0"], fleet, "")
    assert len(calls) == 1 and json.loads((fleet / DONE_FILE).read_text())["checkpoint"] == "ckpt"


def test_the_fleet_finetunes_from_the_recipe_at_its_cpu_budget_where_the_plan_holds_it() -> None:
    """``cpu-small`` plans the recipe as it is, at its own CPU-second budget and world (``hour-intra-uncapped``): its
    fleet and targets read that model; the ``gpu`` preset and a plan without the headline's cell keep the recipe's
    step-budget model (``long``)."""
    assert headline_variant(PRESETS["cpu-small"]) == HOUR_INTRA_UNCAPPED and headline_variant(PRESETS["gpu"]) == LONG
    assert headline_variant(PRESET) == LONG
    assert headline_variant(dataclasses.replace(PRESET, headline=HOUR_INTRA_UNCAPPED)) == LONG  # not in its plan


def test_the_budget_table_has_a_column_per_registered_method_with_its_inputs(monkeypatch: pytest.MonkeyPatch) -> None:
    """Columns in registry order (a fake registered method's results appear), each header with the inputs its
    protocol records; step 0 is zero-shot for a method with a zero-shot model; an unregistered method is refused."""
    monkeypatch.setitem(METHODS, "fake", _fake("fake"))
    results = [_result("s0", "fake", [(0.0, 0.1), (2.0, 0.9)], "rgbd"),
               _result("s0", "2d-transfer", [(0.0, 0.3), (0.5, 0.4)], "rgbd"),
               _result("s0", "sray", [(0.0, 0.2), (0.5, 0.6)], "rgb")]
    header, rows = budget_table(results, (0.0, 1.0, 3.0), lambda v: "—" if v is None else f"{100 * v:.0f}")
    assert header == ["budget s", "S-Ray finetune mIoU % (RGB)", "2d-transfer finetune mIoU % (RGB-D)",
                      "fake label mIoU % (RGB-D)"]
    assert rows == [["0", "20", "30", "10"], ["1", "60", "40", "10"], ["3", "60", "40", "90"]]
    assert step_zero(results) == "zero-shot for S-Ray finetune, 2d-transfer finetune; untrained for fake label"
    with pytest.raises(ValueError, match="unknown method 'gone'"):
        budget_table([_result("s0", "gone", [(0.0, 0.1)], "rgb")], (0.0,), str)


def test_records_stored_before_still_load(tmp_path: Path) -> None:
    """An old-harness cell (no held-out or CPU-time fields), old fleet results (one without a protocol) and the
    equal-budget table stored under its former title: the tables are written, the old table is replaced in place."""
    out, doc = tmp_path / "run", tmp_path / "docs" / "benchmarks.md"
    old_cell = {"cell": "long-s0", "variant": LONG, "seed": 0, "steps": 4, "miou": 0.25, "total_acc": 0.5,
                "class_avg_acc": 0.3, "psnr": 18.0, "train_s": 60.0, "eval_s": 6.0, "class_iou": [0.25, None],
                "class_names": ["wall", "lamp"], "checkpoint": "OUT/ckpt",
                "protocol": EvalProtocol("frustum-overlap v2", 2, 1).to_json()}
    (out / "cells").mkdir(parents=True)
    (out / "cells" / "long-s0.json").write_text(json.dumps(old_cell))
    _store(out / "fleet", _result("s0", "sray", [(0.0, 0.25), (2.0, 0.5)], "rgb"))
    _store(out / "fleet", _result("s0", "semantic-nerf", [(0.0, 0.0), (2.5, 0.3)], None))
    (out / "fleet" / DONE_FILE).write_text(json.dumps({"checkpoint": "OUT/ckpt"}) + "\n")
    bench = accuracy_bench("toy")
    record(bench, "Zero-shot with seeds", "| a |\n| --- |\n| 1 |", doc)
    record(bench, FORMER_TITLES[0], "| budget s |\n| --- |\n| 0 |", doc)

    assert import_old_cells(out) == ["long-s0"] and stored_cells(out) == {"long-s0": old_cell}
    assert methods_done(out / "fleet") == {"sray", "semantic-nerf"}
    write_tables("toy", PRESET, stored_cells(out), out / "fleet", doc)
    tables = json.loads((bench_dir(doc, bench) / "tables.json").read_text())["tables"]
    assert [t["title"] for t in tables] == ["Zero-shot with seeds", BUDGET_TABLE, "Per-class IoU, zero-shot"]
    [budget] = [b for b in tables[1]["blocks"] if "header" in b]
    assert budget["header"] == ["budget s", "S-Ray finetune mIoU % (RGB)",
                                "Semantic-NeRF from scratch mIoU % (inputs not recorded)"]
    assert budget["rows"] == [["0", "25.00", "0.00"], ["1", "25.00", "0.00"], ["3", "50.00", "30.00"]]
    assert "25.00" in json.dumps(tables[0]) and "Missing cells: none." in tables[0]["notes"]
