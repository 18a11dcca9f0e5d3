"""The ``sray gpu-check`` report: one result per stage, kept in a JSON file so a re-run resumes.

``<out>/gpu_check.json`` holds ``{"device": ..., "stages": {name: StageResult}}``; a stage already in
it is skipped by the next run (``--fresh`` starts over). :func:`markdown` renders the whole report: a
summary table (stage, status, seconds, one line) and each stage's own table.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from sray.data_tools.atomic import atomic_write_json
from sray.platform.common.doc_blocks import markdown_table

REPORT_FILE = "gpu_check.json"
STATUSES = ("passed", "failed", "skipped")
STAGE_NAMES = ("environment", "tests", "precision", "training", "recipe", "bench", "profile", "ray", "fleet",
               "minutes")
"""The stages in run order: the choices of ``sray gpu-check --stages`` and the order of the report's table."""


@dataclass
class StageResult:
    """What one stage found."""

    status: str
    """``passed`` (every check within its tolerance), ``failed`` (a check outside it, or an error) or
    ``skipped`` (the machine lacks what the stage needs; ``summary`` says what)."""
    summary: str
    """One line: the headline figures, or why the stage failed or was skipped."""
    seconds: float = 0.0
    """Wall time of the stage."""
    header: list[str] = field(default_factory=list)
    """Column names of the stage's table (empty: no table)."""
    rows: list[list[str]] = field(default_factory=list)
    """The stage's table rows, as printed."""

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"stage status {self.status!r}: use one of {STATUSES}")


def table_cells(table: str) -> tuple[list[str], list[list[str]]]:
    """The header and the body rows of a Markdown table (its ``|`` lines; the separator row after the header
    is skipped), as stripped cell strings: how a stage takes over a benchmark's table."""
    lines = [line.strip().strip("|") for line in table.splitlines() if line.startswith("|")]
    header, _separator, *body = ([c.strip() for c in line.split("|")] for line in lines)
    return header, body


def load_report(out: Path) -> dict:
    """The report in ``out`` (an empty one if there is none yet)."""
    path = out / REPORT_FILE
    if not path.exists():
        return {"device": None, "stages": {}}
    data = json.loads(path.read_text())
    return {"device": data.get("device"), "stages": {k: StageResult(**v) for k, v in data["stages"].items()}}


def save_report(out: Path, report: dict) -> Path:
    """Write the report atomically (temporary file, then rename); returns its path."""
    path = out / REPORT_FILE
    atomic_write_json(path, {"device": report["device"], "stages": {k: asdict(v) for k, v in report["stages"].items()}})
    return path


def markdown(report: dict, order: list[str]) -> str:
    """The report as Markdown: a summary table in stage order, then each stage's table."""
    stages = report["stages"]
    names = [n for n in order if n in stages]
    parts = [markdown_table(["stage", "status", "seconds", "summary"],
                    [[n, stages[n].status, f"{stages[n].seconds:.1f}", stages[n].summary] for n in names])]
    for name in names:
        result = stages[name]
        if result.header:
            parts.append(f"**{name}**\n\n" + markdown_table(result.header, result.rows))
    return "\n\n".join(parts)
