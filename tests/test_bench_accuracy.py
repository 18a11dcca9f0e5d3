"""``sray bench accuracy`` end to end on a toy preset: ablation table, equal-budget table, charts."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sray.jobs.bench import accuracy as bench_accuracy
from sray.jobs.bench.accuracy import VARIANTS, Preset, run_accuracy_benchmark

TOY = Preset(train_scenes=1, test_scenes=1, views=20, height=36, width=48, steps=2, rays=32, n_coarse=4, n_fine=4,
             n_source=2, workers=1, gpus_per_worker=0.0, precision="no", budget_s=3.0, budgets=(1.0, 3.0),
             validations=1, fleet_eval_stride=4)


@pytest.mark.slow
def test_toy_preset_writes_both_tables_and_the_charts(ray_session, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setitem(bench_accuracy.PRESETS, "toy", TOY)
    doc = tmp_path / "docs" / "benchmarks.md"
    run_accuracy_benchmark("toy", tmp_path / "run", doc)
    text = doc.read_text()
    ablation = text.split("## Accuracy: attention ablation, zero-shot (toy)")[1].split("## ")[0]
    rows = [ln for ln in ablation.splitlines() if ln.split(" | ")[0] in VARIANTS]
    assert [r.split(" | ")[0] for r in rows] == list(VARIANTS)
    header = next(ln for ln in ablation.splitlines() if ln.startswith("variant | ")).split(" | ")
    for row in rows:
        cells = dict(zip(header, row.split(" | "), strict=True))
        assert 0.0 <= float(cells["mIoU %"]) <= 100.0
        assert -1.0 <= float(cells["SSIM"]) <= 1.0  # zero-shot evaluations render whole images
    # the protocol line under each table: read from the shards' manifest and the preset
    rule = json.loads((tmp_path / "run" / "shards" / "manifest.json").read_text())["neighbours"]
    source_rule = f"{rule['rule']} v{rule['version']}"
    [caption] = [ln for ln in ablation.splitlines() if ln.startswith("Protocol")]
    assert caption.startswith(f"Protocol: sources: {TOY.n_source} per query, fixed, top-ranked by {source_rule}; "
                              "pixels: whole images (stride 1)")
    budget = text.split("equal wall-clock budgets (toy)")[1]
    budget_rows = [ln.split(" | ") for ln in budget.splitlines() if ln[:1].isdigit()]
    assert [r[0] for r in budget_rows] == ["0", "1", "3"]
    assert all(cell != "-" for r in budget_rows for cell in r[1:])
    captions = {ln.split(": ", 1)[0]: ln for ln in budget.splitlines() if ln.startswith("Protocol")}
    assert set(captions) == {"Protocol (sray)", "Protocol (semantic-nerf)"}
    stride = f"every 4th in each direction (stride {TOY.fleet_eval_stride}), so no SSIM"
    assert f"{TOY.n_source} per query, fixed, top-ranked by {source_rule}" in captions["Protocol (sray)"]
    assert "sources: none (per-scene model)" in captions["Protocol (semantic-nerf)"]
    assert all(stride in c for c in captions.values())
    charts = list((tmp_path / "docs/benchmarks/accuracy-toy").glob("*.png"))
    assert charts and all(f"benchmarks/accuracy-toy/{c.name}" in text for c in charts)
