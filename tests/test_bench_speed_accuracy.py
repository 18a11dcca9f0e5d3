"""``sray bench speed-accuracy`` bookkeeping on hand-made rows: the Pareto front, the paired table, the chart."""

from __future__ import annotations

from pathlib import Path

from sray.jobs.bench.speed_accuracy import chart, pareto, table


def _row(name: str, miou: float, s: float, fast: bool = False) -> dict:
    return {"name": name, "miou": miou, "psnr": 20.0, "s_per_view": s, "views": 4,
            "setting": {"fast": {"pixel_stride": 4} if fast else None}}


ROWS = [_row("full", 50.0, 40.0), _row("slow and worse", 45.0, 60.0), _row("fast a", 49.5, 1.0, True),
        _row("fast b", 40.0, 0.5, True), _row("dominated", 39.0, 0.8, True)]


def test_pareto_front_keeps_only_undominated_rows_fastest_first() -> None:
    assert [r["name"] for r in pareto(ROWS)] == ["fast b", "fast a", "full"]


def test_table_reports_paired_differences_and_speed_ups_against_the_first_row() -> None:
    lines = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[1:-1]] for ln in table(ROWS).splitlines()[2:]}
    assert lines["fast a"][2] == "-0.50" and lines["fast a"][5] == "40.0x" and lines["fast a"][6] == "✓"
    assert lines["full"][2] == "+0.00" and lines["dominated"][6] == ""


def test_chart_is_written(tmp_path: Path) -> None:
    png = chart(ROWS, tmp_path / "sa.png", "protocol line")
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
