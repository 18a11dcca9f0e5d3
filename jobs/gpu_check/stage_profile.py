"""Stage ``profile``: ``sray bench profile`` on this device: the operators with the most self time (self
CUDA time on a GPU) of the paper-config training step in fp32 and bf16 and of a whole-image render, on the
fast path. On a GPU the full tables also go into the "Profiles" section of ``docs/benchmarks.md`` for that GPU."""

from __future__ import annotations

import re

from sray.jobs.bench.profile import run_profiles, write_profiles

from .context import CheckContext
from .report import StageResult, table_cells

TOP_ROWS = 5
"""Operators per profile kept in the report (docs/benchmarks.md gets the whole table)."""


def run(ctx: CheckContext) -> StageResult:
    """Profile the step and the render; the top operators of each profile become the stage's rows."""
    sections = run_profiles(ctx.device, ("fast",), ("train", "render"), quick=ctx.dry_run,
                            step_dtypes=("fp32", "bf16"))
    if not ctx.dry_run:
        write_profiles(sections, ctx.repo / "docs" / "benchmarks.md")
    header = ["profile", "operator", "calls", "self CPU ms", "share of self time", "self CUDA ms"]
    rows, walls = [], []
    for title, table, _notes in sections:
        name = title.removeprefix("Profile: ")
        _, body = table_cells(table)
        rows.extend([name, *cells, *["-"] * (len(header) - 1 - len(cells))] for cells in body[:TOP_ROWS])
        wall = re.search(r"Wall time of the profiled call: ([0-9.]+) s", table)
        walls.append(f"{name} {wall.group(1) if wall else '?'} s")
    return StageResult("passed", "profiled wall time: " + ", ".join(walls), header=header, rows=rows)
