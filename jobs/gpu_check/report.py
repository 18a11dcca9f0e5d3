"""The ``sray gpu-check`` report: ``<out>/gpu_check.json`` holds ``{"device": ..., "stages": {name: StageResult}}``,
so a re-run skips the stages already in it (``--fresh`` starts over)."""

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
    """What one stage found: ``passed`` (every check within its tolerance), ``failed`` (a check outside it, or an
    error) or ``skipped`` (the machine lacks what the stage needs), a one-line summary and the stage's table."""

    status: str
    summary: str
    seconds: float = 0.0
    header: list[str] = field(default_factory=list)
    """Column names of the stage's table (empty: no table)."""
    rows: list[list[str]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"stage status {self.status!r}: use one of {STATUSES}")


def table_cells(table: str) -> tuple[list[str], list[list[str]]]:
    """The header and body rows of a Markdown table as stripped cell strings (the separator row skipped)."""
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


def save_report(out: Path, report: dict) -> None:
    """Write the report atomically."""
    atomic_write_json(out / REPORT_FILE, {"device": report["device"],
                                          "stages": {k: asdict(v) for k, v in report["stages"].items()}})


def markdown(report: dict, order: list[str]) -> str:
    """The report as Markdown: a summary table (stage, status, seconds, summary) in stage order, then each stage's."""
    stages = report["stages"]
    names = [n for n in order if n in stages]
    parts = [markdown_table(["stage", "status", "seconds", "summary"],
                            [[n, stages[n].status, f"{stages[n].seconds:.1f}", stages[n].summary] for n in names])]
    parts += [f"**{n}**\n\n" + markdown_table(stages[n].header, stages[n].rows) for n in names if stages[n].header]
    return "\n\n".join(parts)
