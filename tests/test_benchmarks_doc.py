"""docs/benchmarks.md: one section per benchmark and device kind, rendered from the data stored beside the
benchmark's charts, replaced on a rerun, the rest of the document untouched."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from sray.platform.common import bench_doc
from sray.platform.common.bench_doc import Bench, TableRecord, bench_dir, device_kind, record, store_table
from sray.platform.common.doc_blocks import markdown_table, parse_blocks, portable, render_blocks

LOADER, MODEL = Bench("loader", "Loader"), Bench("model", "Model")
HAND_WRITTEN = "## Written by hand\n\nA paragraph nobody generates.\n\n### Its own table\n\n| x |\n|---|\n| 9 |\n"


def _sections(doc: Path) -> list[str]:
    return [ln[3:] for ln in doc.read_text().splitlines() if ln.startswith("## ")]


def _section(doc: Path, title: str) -> str:
    text = doc.read_text()
    start = text.index(f"## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start:] if end < 0 else text[start:end + 1]


def test_a_rerun_replaces_its_table_in_the_data_and_its_one_section(tmp_path: Path, monkeypatch) -> None:
    """Write twice: one section, one table, the second run's rows in the doc and in ``tables.json``; the other
    benchmark's section and a hand-written section are left byte for byte."""
    doc = tmp_path / "docs" / "benchmarks.md"
    monkeypatch.setattr(sys, "argv", ["sray", "bench", "loader"])
    record(LOADER, "Throughput", "| workers | samples/s |\n|---:|---:|\n| 0 | 1.5 |", doc, "first notes")
    record(MODEL, "Training step", "| a |\n|---|\n| 2 |", doc, "model notes")
    doc.write_text(doc.read_text() + "\n" + HAND_WRITTEN)
    model_before = _section(doc, f"Model ({device_kind()})")

    monkeypatch.setattr(sys, "argv", ["sray", "bench", "loader", "--batches", "3"])
    record(LOADER, "Throughput", "| workers | samples/s |\n|---:|---:|\n| 0 | 2.5 |\n| 1 | 3.0 |", doc, "new notes")

    kind = device_kind()
    assert _sections(doc) == [f"Loader ({kind})", f"Model ({kind})", "Written by hand"]
    text = doc.read_text()
    assert text.startswith("# Benchmarks\n")
    loader = _section(doc, f"Loader ({kind})")
    assert loader.count("### Throughput") == 1 and "| 1 | 3.0 |" in loader and "| 0 | 1.5 |" not in loader
    assert "Command: `sray bench loader --batches 3`" in loader and "new notes" in loader
    assert "first notes" not in text
    assert _section(doc, f"Model ({kind})") == model_before
    assert text.endswith(HAND_WRITTEN)

    data_path = bench_dir(doc, LOADER) / "tables.json"
    assert data_path == tmp_path / "docs" / "benchmarks" / "loader" / bench_doc.device_slug() / "tables.json"
    data = json.loads(data_path.read_text())
    assert data["benchmark"] == "Loader" and data["device"] == kind
    [table] = data["tables"]
    assert table["title"] == "Throughput" and table["command"] == "sray bench loader --batches 3"
    assert table["measured_utc"] and table["machine"] and table["notes"] == "new notes"
    [block] = table["blocks"]
    assert block["header"] == ["workers", "samples/s"] and block["rows"] == [["0", "2.5"], ["1", "3.0"]]
    assert f"benchmarks/loader/{bench_doc.device_slug()}/tables.json" in loader  # the section links its data
    assert not list(tmp_path.rglob("*.tmp"))


def test_a_benchmarks_other_tables_stay_when_one_is_measured_again(tmp_path: Path) -> None:
    """``sray bench model --tables train`` after a full run: the attention table is kept, in its place."""
    doc = tmp_path / "benchmarks.md"
    record(MODEL, "Attention", "| v |\n|---|\n| full |", doc, "attention notes")
    record(MODEL, "Training step", "| s |\n|---|\n| 5.0 |", doc)
    record(MODEL, "Attention", "| v |\n|---|\n| dense |", doc, "attention notes")
    section = _section(doc, f"Model ({device_kind()})")
    assert section.index("### Attention") < section.index("### Training step")
    assert "| dense |" in section and "| full |" not in section and "| 5.0 |" in section
    titles = [t["title"] for t in json.loads((bench_dir(doc, MODEL) / "tables.json").read_text())["tables"]]
    assert titles == ["Attention", "Training step"]


def test_another_devices_section_is_kept_beside_this_ones(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    other = "NVIDIA H200" if device_kind() == "CPU only" else "CPU only"
    store_table(MODEL, TableRecord("Training step", "sray bench model", "elsewhere", "an earlier run",
                                   parse_blocks("| old |\n|---|\n| 1 |")), doc, kind=other)
    record(MODEL, "Training step", "| new |\n|---|\n| 2 |", doc)
    assert _sections(doc) == [f"Model ({other})", f"Model ({device_kind()})"]
    assert "| old |" in doc.read_text() and "| new |" in doc.read_text()
    assert bench_dir(doc, MODEL, other) != bench_dir(doc, MODEL)


def test_shared_notes_and_command_are_shown_once_after_the_tables_that_share_them(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    for axis in ("Blur", "Noise"):
        record(Bench("stability-toy", "Stability, toy"), axis, f"| {axis} |\n|---|\n| 1 |", doc, "shared protocol")
    section = _section(doc, f"Stability, toy ({device_kind()})")
    assert section.count("shared protocol") == 1 and section.index("### Noise") < section.index("shared protocol")
    assert section.count("Command: ") == 1


def test_commands_and_notes_name_repository_relative_paths_or_OUT(tmp_path: Path, monkeypatch) -> None:
    """No machine's absolute folder reaches the document: a path inside the repository becomes relative to it,
    others ``OUT/`` plus their path below the folder their parents share (a SQLite URI too)."""
    repo, run = tmp_path / "repo", tmp_path / "scratch" / "run"
    doc = repo / "docs" / "benchmarks.md"
    monkeypatch.setattr(sys, "argv", ["sray", "bench", "speed-accuracy", "--checkpoint", f"{run}/train/ckpt",
                                      "--data", f"{repo}/outputs/shards", f"--tracking-uri=sqlite:///{run}/m.db"])
    record(LOADER, "Paths", "| a |\n|---|\n| 1 |", doc, f"Checkpoint `{run}/train/ckpt`; shards {repo}/outputs/shards.")
    text = doc.read_text()
    assert str(tmp_path) not in text and str(tmp_path) not in (bench_dir(doc, LOADER) / "tables.json").read_text()
    assert ("`sray bench speed-accuracy --checkpoint OUT/train/ckpt --data outputs/shards "
            "--tracking-uri=sqlite:///OUT/m.db`") in text
    assert "Checkpoint `OUT/train/ckpt`; shards outputs/shards." in text
    assert portable(["a / b and 3/4 and https://x.org/a/b"], repo) == ["a / b and 3/4 and https://x.org/a/b"]


def test_tables_parse_to_rows_and_render_back() -> None:
    """A table with and without outer pipes, a cell holding an escaped pipe, text between tables."""
    md = "\n".join([markdown_table(["k", "v"], [["a|b", 1]]), "", "Some text.", "",
                    "| x | y |", "| --- | ---: |", "| 1 | 2 |"])
    blocks = parse_blocks(md)
    assert [b.get("text") for b in blocks] == [None, "Some text.", None]
    assert blocks[0]["rows"] == [["a\\|b", "1"]] and blocks[0]["outer_pipes"] is False
    assert blocks[2]["align"] == ["---", "---:"] and blocks[2]["outer_pipes"] is True
    assert render_blocks(blocks) == md


def test_an_index_sends_each_section_to_its_benchmarks_page(tmp_path: Path, monkeypatch) -> None:
    """docs/benchmarks.md holding the index marker is left byte for byte; the section goes to
    docs/benchmarks/<slug>.md beside it (a new page starts with its title and a link back), its data stays in
    docs/benchmarks/<slug>/<device>/, the notes' links are rebased onto the page's folder, and the command line
    describes the machine by the stored descriptor."""
    machine = {"cpu_model": "Test CPU 9000", "cores": 3, "device": "cpu", "ray_steps_per_cpu_second": 4.25}
    monkeypatch.setattr(bench_doc, "describe_machine", lambda: machine)
    doc = tmp_path / "docs" / "benchmarks.md"
    doc.parent.mkdir()
    index = f"# Benchmarks\n\n{bench_doc.INDEX_MARKER}\n\n- [Loader](benchmarks/loader.md)\n"
    doc.write_text(index)
    chart = "![chart](benchmarks/loader/cpu-only/speed.png)"
    record(LOADER, "Throughput", "| workers | samples/s |\n|---:|---:|\n| 0 | 1.5 |", doc, f"notes {chart}")
    assert doc.read_text() == index
    page = tmp_path / "docs" / "benchmarks" / "loader.md"
    text = page.read_text()
    assert text.startswith("# Loader\n") and "(../benchmarks.md)" in text
    assert f"## Loader ({device_kind()})" in text and "| 0 | 1.5 |" in text
    assert "![chart](loader/cpu-only/speed.png)" in text
    assert "Test CPU 9000, 3 cores, cpu, 4.25 probe steps per CPU second" in text
    stored = json.loads((bench_dir(doc, LOADER) / "tables.json").read_text())["tables"][0]
    assert stored["machine_descriptor"] == machine
    assert bench_dir(doc, LOADER) == tmp_path / "docs" / "benchmarks" / "loader" / bench_doc.device_slug()
    record(MODEL, "Training step", "| a |\n|---|\n| 2 |", doc)
    record(LOADER, "Throughput", "| workers | samples/s |\n|---:|---:|\n| 0 | 2.5 |", doc, f"notes {chart}")
    assert "| 2.5 |" in page.read_text() and "| 1.5 |" not in page.read_text()
    assert "## Model" in (tmp_path / "docs" / "benchmarks" / "model.md").read_text() and "## Model" not in text
