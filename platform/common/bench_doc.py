"""Benchmark tables stored as data beside their charts (``benchmarks/<bench>/<device>/tables.json``), each (benchmark,
device) rendered as a section of ``doc``, or of the benchmark's page when ``doc`` is an index (:data:`INDEX_MARKER`)."""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform as _stdlib_platform
import re
import shlex
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

from sray.data_tools.atomic import atomic_write_json, atomic_write_text
from sray.platform.common.doc_blocks import parse_blocks, portable, rebase_links, render_blocks
from sray.platform.common.machine import describe_machine

DEFAULT_DOC = Path("docs/benchmarks.md")
DATA_FILE = "tables.json"
INDEX_MARKER = "<!-- benchmarks index: each benchmark's sections are on its page benchmarks/<benchmark>.md -->"
"""The line that makes a document an index: sections go to the benchmarks' pages."""


@dataclass(frozen=True)
class Bench:
    """A benchmark: ``slug`` names its folder under ``docs/benchmarks/``, ``title`` its section."""

    slug: str
    title: str


@dataclass
class TableRecord:
    """One measured table as stored in a benchmark's ``tables.json``."""

    title: str
    command: str
    machine: str
    """``machine_line()`` when it was measured."""
    measured_utc: str
    blocks: list[dict]
    """``doc_blocks.parse_blocks`` of the table's Markdown."""
    notes: str = ""
    machine_descriptor: dict | None = None
    """``describe_machine()`` of the machine that measured it (None: stored before machines were described)."""


def device_kind() -> str:
    """The accelerator a number was measured on: the CUDA device's name, or 'CPU only'."""
    return torch.cuda.get_device_name(0) if torch.cuda.is_available() else "CPU only"


def device_slug(kind: str | None = None) -> str:
    """``kind`` (default: this device's) as a folder name: ``CPU only`` -> ``cpu-only``."""
    return re.sub(r"[^a-z0-9]+", "-", (kind or device_kind()).lower()).strip("-")


def bench_dir(doc: Path, bench: Bench, kind: str | None = None) -> Path:
    """The folder of ``bench``'s data and charts on this (or ``kind``) device, beside ``doc``."""
    return Path(doc).parent / "benchmarks" / bench.slug / device_slug(kind)


def bench_page(doc: Path, bench: Bench) -> Path:
    """``doc``, or the page ``benchmarks/<slug>.md`` beside it when ``doc`` is an index."""
    doc = Path(doc)
    return doc.parent / "benchmarks" / f"{bench.slug}.md" if doc.exists() and INDEX_MARKER in doc.read_text() else doc


def page_header(bench: Bench, page: Path, doc: Path) -> str:
    """The first lines of a new page of ``bench``: its title and a link back to the index ``doc``."""
    index = os.path.relpath(doc, page.parent)
    return (f"# {bench.title}\n\nGenerated from the data beside its charts by the command each table names; listed in "
            f"[the benchmarks index]({index}).\n")


def machine_line() -> str:
    """One line naming the machine a number was measured on."""
    device = device_kind()
    if not torch.cuda.is_available():
        device += (f", {torch.get_num_threads()} torch threads, {os.cpu_count()} cores, "
                   f"load average {_load()} when written")
    return (f"{_stdlib_platform.machine()}, {device}, torch {torch.__version__}, "
            f"Python {_stdlib_platform.python_version()}")


def _load() -> str:
    """The 1-minute load average (other processes on a shared CPU make times noisy), or '?'."""
    try:
        return f"{os.getloadavg()[0]:.1f}"
    except OSError:
        return "?"


_HEADER = ("# Benchmarks\n\nOne section per benchmark and kind of device, generated from the data beside its "
           "charts (`benchmarks/<benchmark>/<device>/tables.json`); rerunning a table's command on the same "
           "kind of device replaces that table. Ratios are measured side by side in one run.\n")


def record(bench: Bench, title: str, table_markdown: str, doc: Path = DEFAULT_DOC, notes: str = "",
           kind: str | None = None, replaces: tuple[str, ...] = ()) -> str:
    """Print a measured table and :func:`store_table` it as ``title``, with this process's command line."""
    command = "sray " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    folder = Path(os.path.abspath(doc)).parent
    repo = folder.parent if folder.name == "docs" else Path.cwd()  # the repository the document belongs to
    command, table_markdown, notes = portable([command, table_markdown, notes], repo)
    entry = TableRecord(title=title, command=command, machine=machine_line(), notes=notes.strip(),
                        measured_utc=_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%MZ"),
                        blocks=parse_blocks(table_markdown), machine_descriptor=describe_machine())
    print(f"\n### {title}\n\n{render_blocks(entry.blocks)}\n\n{entry.notes}\n".rstrip() + "\n")
    return store_table(bench, entry, doc, kind, replaces)


def store_table(bench: Bench, entry: TableRecord, doc: Path = DEFAULT_DOC, kind: str | None = None,
                replaces: tuple[str, ...] = ()) -> str:
    """Put ``entry`` into ``tables.json`` in place of its title's (or a former title's) and rewrite the section."""
    kind = kind or device_kind()
    data_path = bench_dir(doc, bench, kind) / DATA_FILE
    data = (json.loads(data_path.read_text()) if data_path.exists()
            else {"benchmark": bench.title, "device": kind, "tables": []})
    tables, titles = data["tables"], {entry.title, *replaces}
    slot = next((i for i, t in enumerate(tables) if t["title"] in titles), len(tables))
    tables = data["tables"] = [*tables[:slot], asdict(entry), *(t for t in tables[slot:] if t["title"] not in titles)]
    atomic_write_json(data_path, data)
    page = bench_page(doc, bench)
    section = render_section(bench, kind, [TableRecord(**t) for t in tables], doc, page)
    header = page_header(bench, page, doc) if page != doc else _HEADER
    replace_section(page, section_title(bench, kind), section, header)
    return section


def section_title(bench: Bench, kind: str) -> str:
    """The heading of ``bench``'s section on device ``kind``."""
    return f"{bench.title} ({kind})"


def render_section(bench: Bench, kind: str, tables: list[TableRecord], doc: Path, page: Path | None = None,
                   data_file: str = DATA_FILE, title: str | None = None) -> str:
    """The section's Markdown on ``page`` (default ``doc``): its data's link, then each table, command and notes."""
    page = Path(page or doc)
    data_link = os.path.relpath(bench_dir(doc, bench, kind) / data_file, page.parent)
    parts = [f"## {title or section_title(bench, kind)}", f"Its data: [`{data_link}`]({data_link})."]
    for i, t in enumerate(tables):
        parts.append(f"### {t.title}")
        if i == 0 or (t.command, t.machine) != (tables[i - 1].command, tables[i - 1].machine):
            parts.append(f"Command: `{t.command}` — {t.machine}{described(t.machine_descriptor)}")
        if t.blocks:
            parts.append(rebase_links(render_blocks(t.blocks), Path(doc).parent, page.parent))
        if t.notes and (i == len(tables) - 1 or tables[i + 1].notes != t.notes):
            parts.append(rebase_links(t.notes, Path(doc).parent, page.parent))
    return "\n\n".join(parts) + "\n"


def described(descriptor: dict | None) -> str:
    """The machine descriptor as a clause of the command line ('' for a table stored without one)."""
    return (f"; {descriptor['cpu_model']}, {descriptor['cores']} cores, {descriptor['device']}, "
            f"{descriptor['ray_steps_per_cpu_second']} probe steps per CPU second") if descriptor else ""


def replace_section(doc: Path, title: str, section: str, header: str = _HEADER) -> None:
    """Write ``section`` into ``doc`` in place of ``## title`` (else at the end); ``header`` starts a new doc."""
    preamble, *sections = re.split(r"(?m)^(?=## )", doc.read_text() if doc.exists() else header)
    slot = next((i for i, old in enumerate(sections) if old.splitlines()[0].strip() == f"## {title}"),
                len(sections))
    sections[slot:slot + 1] = [section]
    atomic_write_text(doc, "\n".join(part.strip("\n") + "\n" for part in [preamble, *sections]))
