"""``sray lab view-weights``: what each checkpoint's weight net gives the source views occluded at a surface point.

Measures :mod:`sray.lab.view_weights.measure` for one or more checkpoints on the same unseen test views and
sources, stores the rows as ``view-weights.json`` in ``--out``, prints the Markdown table and writes it into the
benchmark document's section "Ceilings" of this device (beside the ceilings table, replaced on a rerun).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sray.lab.ceilings.report import CEILINGS
from sray.lab.view_weights.measure import measure_view_weights
from sray.platform.checkpoints.folders import read_meta
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.common.bench_doc import record
from sray.platform.common.doc_blocks import markdown_table
from sray.platform.eval.zero_shot import write_json_atomic

TITLE = "Weights on occluded source views"
REPORT_FILE = "view-weights.json"


def _num(value: float | None, scale: float = 1.0, digits: int = 3) -> str:
    """``value * scale`` with ``digits`` decimals, "—" when there is none."""
    return "—" if value is None else f"{scale * value:.{digits}f}"


def view_weights_table(rows: list[dict[str, Any]]) -> str:
    """The Markdown table of the measured rows, one per checkpoint."""
    header = ["checkpoint", "τ", "surface points", "n·w sd", "occluded views %", "n·w visible",
              "n·w occluded", "ranking", "occluded mass (plain mean / floor)", "removable mass removed %",
              "surface acc, some view occluded %", "surface acc, all views see %"]
    body = [[f"`{r['name']}`", f"{r['tau']:g}", f"{r['points']:,}", _num(r["relative_weight_sd"]),
             _num(r["occluded_share"], 100, 1), _num(r["visible_relative_weight"]),
             _num(r["occluded_relative_weight"]), _num(r["ranking"]),
             f"{_num(r['occluded_mass'])} ({_num(r['occluded_mass_plain'])} / {_num(r['occluded_mass_floor'])})",
             _num(r["removed_share"], 100, 1), _num(r["acc_occluded"], 100, 1), _num(r["acc_clear"], 100, 1)]
            for r in rows]
    return markdown_table(header, body)


def view_weights_notes(rows: list[dict[str, Any]]) -> str:
    """The protocol lines printed under the table."""
    r = rows[0]
    views = f"the first {r['views_per_scene']} test view(s)" if r["views_per_scene"] else "every test view"
    return (f"Shards `{r['shards']}`: {len(r['scenes'])} unseen test scene(s), {views} of each, {r['n_source']} "
            f"fixed sources (as zero-shot evaluation), one labelled pixel with known depth in {r['stride']} in each "
            "direction; each checkpoint's fine field read at the ground-truth surface (an oracle placement, as "
            "ceiling row d). A valid view is visible at the point when its depth agrees within "
            f"{r['tolerance']:g} (relative), occluded when the point lies behind its surface by more. n·w: a view's "
            "weight relative to the plain mean (1 = the mean; C(τ) allows τ to 1/τ). Ranking: share of (occluded, "
            "visible) view pairs of a point in which the occluded view weighs less (0.5 = blind, 1 = perfect). "
            "Occluded mass: the occluded views' summed weight on points with both kinds of view, beside the plain "
            "mean's and the least C(τ) allows; removed: (plain − actual) / (plain − floor). Surface accuracy: the "
            "field's argmax at the point against its label.")


def run_view_weights(checkpoints: list[Path], shards: Path, out: Path, doc: Path, *, n_source: int = 8,
                     views_per_scene: int = 0, stride: int = 2, tolerance: float = 0.05,
                     progress: bool = True) -> list[dict[str, Any]]:
    """Measure every checkpoint, store ``out/view-weights.json``, print and record the table in ``doc``; returns
    the rows (one per checkpoint, in the order given)."""
    rows = []
    for checkpoint in checkpoints:
        checkpoint = Path(checkpoint).resolve()
        net, _ = model_from_checkpoint(checkpoint)
        step = int(read_meta(checkpoint)["step"])
        report = measure_view_weights(net, Path(shards).resolve(), n_source=n_source, views_per_scene=views_per_scene,
                                      stride=stride, tolerance=tolerance, progress=progress)
        rows.append({"checkpoint": str(checkpoint), "step": step,
                     "name": f"{checkpoint.parent.parent.name}/{checkpoint.name}", **report})
    path = write_json_atomic(rows, Path(out) / REPORT_FILE)
    record(CEILINGS, TITLE, view_weights_table(rows), Path(doc), view_weights_notes(rows))
    print(f"rows stored in {path}")
    return rows
