"""Zero-shot scores on several test splits side by side and the mIoU gap from the first split, the headline of a
shift evaluation (``sray eval --split``): each row from the ``mean`` block of a report, in percent (gaps in points)."""

from __future__ import annotations

from typing import Any

from sray.platform.eval.zero_shot import text_cell, text_table

SPLITS_FILE = "splits.json"
"""File of a shift evaluation's output folder holding :func:`split_summary`."""


def split_summary(reports: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """``{"reference", "splits": {name: {rooms, views, miou, total_acc, class_avg_acc, gap_miou, seconds_per_view}},
    "largest_gap": {split, points}}`` from reports by split name (the first is the reference)."""
    if not reports:
        raise ValueError("split_summary needs at least one report")
    rows: dict[str, dict[str, Any]] = {}
    for name, report in reports.items():
        level, views, wall = report["mean"]["dataset_level"], report["mean"]["n_views"], report.get("wall_s")
        scores = {k: None if level[k] is None else 100.0 * level[k] for k in ("miou", "total_acc", "class_avg_acc")}
        rows[name] = {"rooms": len(report["scenes"]), "views": views, **scores,
                      "seconds_per_view": None if wall is None or not views else wall / views}
    reference = next(iter(rows))
    ref = rows[reference]["miou"]
    for row in rows.values():
        row["gap_miou"] = None if ref is None or row["miou"] is None else ref - row["miou"]
    gaps = [(row["gap_miou"], name) for name, row in rows.items() if name != reference and row["gap_miou"] is not None]
    largest = max(gaps, default=None)
    return {"reference": reference, "splits": rows,
            "largest_gap": None if largest is None else {"split": largest[1], "points": largest[0]}}


def format_splits(summary: dict[str, Any]) -> str:
    """A plain-text table of :func:`split_summary`, one row per split, then the headline gap."""
    rows = [("split", "rooms", "views", "mIoU %", "total acc %", "class acc %", "gap pts", "s/view")]
    for name, r in summary["splits"].items():
        rows.append((name, str(r["rooms"]), str(r["views"]), text_cell(r["miou"], ".1f"),
                     text_cell(r["total_acc"], ".1f"), text_cell(r["class_avg_acc"], ".1f"),
                     text_cell(r["gap_miou"], "+.1f"), text_cell(r["seconds_per_view"], ".2f")))
    largest = summary["largest_gap"]
    headline = ("no shifted split scored" if largest is None else
                f"largest gap: {largest['points']:.1f} mIoU points ({summary['reference']} -> {largest['split']})")
    return "\n".join([*text_table(rows), headline])
