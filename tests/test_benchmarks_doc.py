"""docs/benchmarks.md keeps one section per benchmark and device kind, rewritten atomically."""

from __future__ import annotations

from pathlib import Path

from sray.jobs.bench.doc import device_kind, record


def _titles(doc: Path) -> list[str]:
    return [ln[3:] for ln in doc.read_text().splitlines() if ln.startswith("## ")]


def test_rerun_replaces_its_section_and_keeps_the_others(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    record("Loader", "| a |\n|---|\n| 1 |", doc)
    record("Model", "| b |\n|---|\n| 2 |", doc, notes="model notes")
    record("Loader", "| a |\n|---|\n| 3 |", doc)
    text = doc.read_text()
    assert text.startswith("# Benchmarks\n")
    assert _titles(doc) == ["Loader", "Model"]
    assert "| 3 |" in text and "| 1 |" not in text
    assert "| 2 |" in text and "model notes" in text
    assert "\n\n## Model" in text  # sections stay separated by a blank line
    assert not (tmp_path / "benchmarks.md.tmp").exists()


def test_a_section_from_another_device_is_kept_beside_the_new_one(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    other = "NVIDIA H200" if device_kind() == "CPU only" else "CPU only"
    doc.write_text("# Benchmarks\n\nintro\n\n## Model\n\nCommand: `sray bench model` — 2026-01-01 00:00 UTC — "
                   f"x86_64, {other}, torch 2.13.0, Python 3.11.7\n\n| old |\n")
    record("Model", "| new |\n|---|\n| 1 |", doc)
    text = doc.read_text()
    assert _titles(doc) == ["Model", "Model"]
    assert "| old |" in text and "| new |" in text and "intro" in text
