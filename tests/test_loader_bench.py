"""``sray bench loader``: a table per worker count and an exact bytes-per-view figure."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import scene_fixtures

from sray.data_tools.shards.manifest import read_manifest
from sray.data_tools.shards.writer import write_shards
from sray.jobs.bench import loader_throughput as loader_bench


def _check_report(title: str, table: str, notes: str, shards: Path | None) -> None:
    """Rows for 0/1/2 workers with consistent rates; bytes per view recomputed from the files."""
    rows = [line for line in table.splitlines() if re.match(r"\| \d ", line)]
    assert title and [int(r.split("|")[1]) for r in rows] == [0, 1, 2]
    for row in rows:
        first, samples, rays = (float(c.replace(",", "")) for c in row.split("|")[2:5])
        assert first > 0 and samples > 0 and rays == pytest.approx(samples * 1024, rel=0.01, abs=1)
    if shards is not None:
        manifest = read_manifest(shards)
        total = sum((shards / s.path).stat().st_size for s in manifest.shards)
        per_view = total / sum(s.n_views for s in manifest.shards) / 1024
        assert f"**{per_view:.1f} KiB per view**" in notes


def test_bench_on_given_shards_reports_each_worker_count(tmp_path: Path) -> None:
    """Rows for 0, 1 and 2 workers with positive rates; bytes per view = shard bytes / views."""
    scenes = scene_fixtures.write_dataset(tmp_path / "scenes", [("a", 6, "train"), ("b", 6, "train")])
    write_shards(scenes, tmp_path / "shards", views_per_shard=4, progress=False)
    _check_report(*loader_bench.run_loader_benchmark(tmp_path / "shards", batches=3), tmp_path / "shards")


def test_bench_generates_procedural_shards_when_no_data(monkeypatch: pytest.MonkeyPatch) -> None:
    """With no data the benchmark synthesises, shards and times its own scenes (shrunk here for speed)."""
    monkeypatch.setattr(loader_bench, "BENCH_SCENES", 1)
    monkeypatch.setattr(loader_bench, "BENCH_VIEWS", 6)
    monkeypatch.setattr(loader_bench, "BENCH_HW", (24, 32))
    title, table, notes = loader_bench.run_loader_benchmark(None, batches=2)
    _check_report(title, table, notes, None)
    assert "procedural" in notes and "6 views at 32x24" in notes
