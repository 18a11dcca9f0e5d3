"""Zero-shot scores on several test splits side by side (in-distribution, appearance-shifted, geometry-shifted, ...)
and the gap from the first split, the headline number of a shift evaluation (``sray eval --split``).

A split's row is read from the ``mean`` block of its :func:`~sray.platform.eval.zero_shot.evaluate_model` report
(the dataset-level protocol, scenes averaged); scores are in percent, the gap in points (first split minus this).
"""

from __future__ import annotations

from typing import Any

SPLITS_FILE = "splits.json"
"""File of a shift evaluation's output folder holding :func:`split_summary`."""


def split_summary(reports: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """``{"reference": first split, "splits": {name: {rooms, views, miou, total_acc, class_avg_acc, gap_miou,
    seconds_per_view}}, "largest_gap": {split, points}}`` from reports by split name (first = reference).

    Scores in percent (None where a report has none), ``gap_miou`` = reference mIoU - this split's, in points.
    """
    if not reports:
        raise ValueError("split_summary needs at least one report")
    rows: dict[str, dict[str, Any]] = {}
    for name, report in reports.items():
        mean = report["mean"]
        level = mean["dataset_level"]
        views = mean["n_views"]
        wall = report.get("wall_s")
        rows[name] = {"rooms": len(report["scenes"]), "views": views,
                      **{k: _percent(level[k]) for k in ("miou", "total_acc", "class_avg_acc")},
                      "seconds_per_view": None if wall is None or not views else wall / views}
    reference = next(iter(rows))
    ref = rows[reference]["miou"]
    for row in rows.values():
        row["gap_miou"] = None if ref is None or row["miou"] is None else ref - row["miou"]
    gaps = [(row["gap_miou"], name) for name, row in rows.items() if name != reference and row["gap_miou"] is not None]
    largest = max(gaps, default=None)
    return {"reference": reference, "splits": rows,
            "largest_gap": None if largest is None else {"split": largest[1], "points": largest[0]}}


def _percent(value: float | None) -> float | None:
    return None if value is None else 100.0 * value


def format_splits(summary: dict[str, Any]) -> str:
    """A plain-text table of :func:`split_summary`, one row per split, then the headline gap."""
    head = ("split", "rooms", "views", "mIoU %", "total acc %", "class acc %", "gap pts", "s/view")
    rows = [head]

    def cell(v: Any, fmt: str) -> str:
        return "—" if v is None else format(v, fmt)

    for name, r in summary["splits"].items():
        rows.append((name, str(r["rooms"]), str(r["views"]), cell(r["miou"], ".1f"), cell(r["total_acc"], ".1f"),
                     cell(r["class_avg_acc"], ".1f"), cell(r["gap_miou"], "+.1f"), cell(r["seconds_per_view"], ".2f")))
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    lines = ["  ".join(v.ljust(w) if i == 0 else v.rjust(w) for i, (v, w) in enumerate(zip(r, widths))) for r in rows]
    lines.insert(1, "-" * len(lines[0]))
    largest = summary["largest_gap"]
    headline = ("no shifted split scored" if largest is None else
                f"largest gap: {largest['points']:.1f} mIoU points ({summary['reference']} -> {largest['split']})")
    return "\n".join([*lines, headline])
