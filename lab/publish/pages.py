"""The benchmarks' generated pages, ``docs/benchmarks/<benchmark>.md``: one section per stored data file of the
benchmark (``docs/benchmarks/<benchmark>/<device>/*.json`` holding ``tables``), rendered as ``sray bench`` writes its
own section, the ``tables.json`` of each device first; a hand-written ``## Reading`` section is kept at the end."""

from __future__ import annotations

import json
import re
from pathlib import Path

from sray.lab.publish.bench_data import DATA_FILE, Bench, TableRecord, page_header, render_section, section_title

READING = "## Reading"
"""The heading of a page's hand-written section (at most 15 lines, no measured figure: tests say so)."""


def data_files(docs: Path, slug: str) -> list[Path]:
    """The stored table files of benchmark ``slug``: per device folder, ``tables.json`` first, then the others."""
    folder = Path(docs) / "benchmarks" / slug
    files = []
    for device in sorted(p for p in folder.iterdir() if p.is_dir()):
        for path in sorted(device.glob("*.json"), key=lambda p: (p.name != DATA_FILE, p.name)):
            if "tables" in json.loads(path.read_text()):
                files.append(path)
    return files


def slugs(docs: Path) -> list[str]:
    """Every benchmark with stored tables under ``docs/benchmarks/``."""
    root = Path(docs) / "benchmarks"
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if p.is_dir() and data_files(docs, p.name))


def _label(path: Path) -> str:
    """The heading suffix of a side data file: ``recipe_full_cra_tables.json`` -> ``recipe full cra``."""
    return re.sub(r"_?tables$", "", path.stem).replace("_", " ")


def reading(page: Path) -> str:
    """The page's hand-written ``## Reading`` section as it stands ('' when the page or the section is absent)."""
    if not page.exists():
        return ""
    text = page.read_text()
    start = text.find(f"\n{READING}\n")
    if start < 0:
        return ""
    end = text.find("\n## ", start + 1)
    return text[start + 1:] if end < 0 else text[start + 1:end + 1]


def render_page(docs: Path, slug: str) -> str:
    """The whole page of benchmark ``slug`` from its stored data (and its kept Reading)."""
    docs = Path(docs)
    index, page = docs / "benchmarks.md", docs / "benchmarks" / f"{slug}.md"
    parts, bench = [], None
    for path in data_files(docs, slug):
        data = json.loads(path.read_text())
        bench = bench or Bench(slug, data["benchmark"])
        title = section_title(bench, data["device"]) + ("" if path.name == DATA_FILE else f", {_label(path)}")
        tables = [TableRecord(**t) for t in data["tables"]]
        parts.append(render_section(bench, data["device"], tables, index, page, path.name, title))
    if bench is None:
        raise ValueError(f"{docs / 'benchmarks' / slug}: no stored tables; run the benchmark first")
    kept = reading(page)
    return "\n".join(part.strip("\n") + "\n" for part in [page_header(bench, page, index), *parts, *([kept] if kept
                                                                                                   else [])])
