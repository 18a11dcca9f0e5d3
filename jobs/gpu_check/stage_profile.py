"""Stage ``profile``: ``sray bench profile`` on this device: the operators with the most self time (self
CUDA time on a GPU) of the paper-config training step in fp32 and bf16 and of a whole-image render, on the
fast path. On a GPU the full sections also go into ``docs/performance.md``, beside the CPU ones."""

from __future__ import annotations

from .context import CheckContext
from .report import StageResult

TOP_ROWS = 5
"""Operators per profile kept in the report (docs/performance.md gets the whole table)."""


def run(ctx: CheckContext) -> StageResult:
    """Profile the step and the render; the top operators of each profile become the stage's rows."""
    from sray.jobs.bench.profile import run_profiles, write_profiles

    sections = run_profiles(ctx.device, ("fast",), ("train", "render"), quick=ctx.dry_run,
                            step_dtypes=("fp32", "bf16"))
    if not ctx.dry_run:
        write_profiles(sections, ctx.repo / "docs" / "performance.md")
    header = ["profile", "operator", "calls", "self CPU ms", "share of self time", "self CUDA ms"]
    rows, walls = [], []
    for title, table, _notes in sections:
        lines = table.splitlines()
        body = [line for line in lines[2:] if line.startswith("|")]
        for line in body[:TOP_ROWS]:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            rows.append([title.removeprefix("Profile: "), *cells, *["-"] * (len(header) - 1 - len(cells))])
        wall = next(line for line in lines if line.startswith("Wall time"))
        walls.append(f"{title.removeprefix('Profile: ')} {wall.split(': ')[1].split(' ')[0]} s")
    return StageResult("passed", "profiled wall time: " + ", ".join(walls), header=header, rows=rows)
