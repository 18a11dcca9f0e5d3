"""Benchmarks are printed and appended to ``docs/benchmarks.md`` with the command that made them."""

from __future__ import annotations

import datetime as _dt
import os
import platform as _stdlib_platform
import re
import shlex
import sys
from pathlib import Path

import torch

from sray.data_tools.atomic import atomic_write_text

DEFAULT_DOC = Path("docs/benchmarks.md")


def device_kind() -> str:
    """The accelerator a number was measured on: the CUDA device's name, or 'CPU only'."""
    return torch.cuda.get_device_name(0) if torch.cuda.is_available() else "CPU only"


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


_HEADER = ("# Benchmarks\n\nEvery section below was written by the command it names; a rerun on the same "
           "kind of device replaces its section, another device adds one. Ratios are measured side by side "
           "in one run.\n")


def _split_sections(text: str) -> tuple[str, list[str]]:
    """The document's preamble and its ``## `` sections, each with its trailing text."""
    parts = re.split(r"(?m)^(?=## )", text)
    return parts[0], parts[1:]


def _same_slot(section: str, title: str) -> bool:
    """Whether ``section`` holds the benchmark ``title`` measured on this kind of device."""
    lines = section.splitlines()
    if not lines or lines[0].strip() != f"## {title}":
        return False
    command = next((ln for ln in lines if ln.startswith("Command: ")), "")
    return f", {device_kind()}," in command or command.endswith(f", {device_kind()}")


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    """A Markdown table: the header, its rule, one line per row (cells converted with ``str``)."""
    lines = [" | ".join(header), " | ".join("---" for _ in header)]
    return "\n".join(lines + [" | ".join(str(c) for c in r) for r in rows])


def record(title: str, table_markdown: str, doc: Path = DEFAULT_DOC, notes: str = "", header: str = _HEADER) -> str:
    """Print a benchmark section and write it into ``doc``; returns the section text.

    A section with the same title measured on the same kind of device is replaced in place (so the
    document holds the latest numbers once per device); otherwise the section is appended. The file
    is rewritten through a temporary file and a rename, so an interrupted run leaves it intact.
    ``header`` starts a document that does not exist yet.
    """
    command = "sray " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    section = (f"## {title}\n\nCommand: `{command}` — {stamp} — {machine_line()}\n\n"
               f"{table_markdown.strip()}\n")
    if notes:
        section += f"\n{notes.strip()}\n"
    print("\n" + section)
    preamble, sections = _split_sections(doc.read_text() if doc.exists() else header)
    slot = next((i for i, old in enumerate(sections) if _same_slot(old, title)), len(sections))
    sections[slot:slot + 1] = [section]
    text = "\n".join(part.strip("\n") + "\n" for part in [preamble, *sections])
    atomic_write_text(doc, text)
    return section
