"""Benchmarks are printed and appended to ``docs/benchmarks.md`` with the command that made them."""

from __future__ import annotations

import datetime as _dt
import platform as _stdlib_platform
import shlex
import sys
from pathlib import Path

import torch

DEFAULT_DOC = Path("docs/benchmarks.md")


def machine_line() -> str:
    """One line naming the machine a number was measured on."""
    if torch.cuda.is_available():
        device = torch.cuda.get_device_name(0)
    else:
        device = f"CPU only, {torch.get_num_threads()} torch threads"
    return f"{_stdlib_platform.machine()}, {device}, torch {torch.__version__}, Python {_stdlib_platform.python_version()}"


def record(title: str, table_markdown: str, doc: Path = DEFAULT_DOC, notes: str = "") -> str:
    """Print a benchmark section and append it to ``doc``; returns the section text."""
    command = "sray " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    section = (f"\n## {title}\n\nCommand: `{command}` — {stamp} — {machine_line()}\n\n"
               f"{table_markdown.strip()}\n")
    if notes:
        section += f"\n{notes.strip()}\n"
    print(section)
    doc.parent.mkdir(parents=True, exist_ok=True)
    if not doc.exists():
        doc.write_text("# Benchmarks\n\nEvery section below was appended by the command it names; "
                       "ratios are measured side by side in one run.\n")
    with open(doc, "a") as f:
        f.write(section)
    return section
