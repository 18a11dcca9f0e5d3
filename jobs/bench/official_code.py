"""The paper's public S-Ray code against sray's training step, from a same-run side-by-side measurement.

The comparison is made by the shared tool ``official_side_by_side/run.py`` (beside the checkout, in the
shared tools folder): fresh processes alternating between the official code at its own configuration
(1024 rays, 64+64 samples, 8 views, 320x240, fp32; with and without ``THP_MEM_ALLOC_ENABLE=1``), sray's
default step and sray's unoptimised reference path, on one machine in one run. It stores the raw step
times as ``results.json``; :func:`official_side_by_side` turns that file into a table for
``sray bench model --official-side-by-side FILE``, so every ratio stated is one of that run, never a
number carried over from another.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

from sray.platform.common.doc_blocks import markdown_table

TITLE = "Official S-Ray code against sray, same run"
SRAY_DEFAULT = "sray default (no THP)"
"""The tool's name of sray's default step, the row every ratio divides by."""


def _summary(runs: list[dict]) -> dict:
    """Median seconds per step over every timed step (the first of each process is its warm-up), the
    per-process medians, and the median peak RSS in GiB."""
    timed = [t for r in runs for t in r["times"][1:]]
    return {"median": statistics.median(timed), "min": min(timed), "max": max(timed),
            "per_round": [statistics.median(r["times"][1:]) for r in runs],
            "rss_gib": statistics.median(r["rss_bytes"] for r in runs) / 2**30}


def official_side_by_side(results_json: Path) -> tuple[str, str, str]:
    """(title, Markdown table, notes) of the tool's ``results.json``: per variant the median seconds per step,
    range, per-process medians and peak RSS, and the time and memory against sray's default of the same run."""
    results = json.loads(Path(results_json).read_text())
    if SRAY_DEFAULT not in results:
        raise ValueError(f"{results_json}: no {SRAY_DEFAULT!r} row; pass the results.json that "
                         "official_side_by_side/run.py wrote")
    stats = {name: _summary(runs) for name, runs in results.items() if runs}
    base = stats[SRAY_DEFAULT]
    rows = [[name, f"{s['median']:.2f}", f"{s['min']:.2f}–{s['max']:.2f}",
             " / ".join(f"{x:.2f}" for x in s["per_round"]), f"{s['rss_gib']:.2f}",
             f"{s['median'] / base['median']:.2f}x", f"{s['rss_gib'] / base['rss_gib']:.2f}x"]
            for name, s in stats.items()]
    table = markdown_table(["variant", "median s / step", "min–max", "per-process medians", "peak RSS GiB",
                            "time / sray default", "memory / sray default"], rows)
    first = next(iter(results.values()))[0]
    processes = max(len(runs) for runs in results.values())
    notes = (f"The paper's public S-Ray code (its own renderer, losses, gradient clipping and Adam, random "
             f"inputs) and sray at the paper code config (1024 rays, 64+64 samples, 8 views, 320x240, fp32), "
             f"{processes} fresh process(es) per variant alternating round by round, one warm-up step each, "
             f"median over the timed steps; peak RSS is the process's VmHWM; torch {first.get('torch', '?')}, "
             f"{first.get('threads', '?')} threads. Made by the shared tools' `official_side_by_side/run.py "
             f"--checkout . --git-dir OFFICIAL_GIT_DIR`, which writes `OUT/ofc/runs/<stamp>/results.json`.")
    return TITLE, table, notes
