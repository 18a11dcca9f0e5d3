"""``sray lab ceilings``: where zero-shot accuracy is lost, as a table.

``ceilings`` scores the rows of :mod:`sray.lab.ceilings.measure` on a checkpoint's unseen test scenes (or on
held-out views of its training scenes), stores them as ``ceilings.json`` in ``--out``, prints the Markdown table and
writes it into the benchmark document's section "Ceilings" of this device (replaced on a rerun on the same kind of
device and views). The 2D segmenter some rows read is trained by the product's ``sray bench segmenter``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sray.lab.ceilings.measure import ZERO_SHOT_RENDER, measure_ceilings
from sray.model.fast_render import FastRender
from sray.platform.common.bench_doc import Bench, record
from sray.platform.common.doc_blocks import markdown_table
from sray.platform.eval.zero_shot import write_json_atomic

CEILINGS = Bench("ceilings", "Ceilings")
"""The benchmark's section in docs/benchmarks.md."""
TITLE = "Where zero-shot accuracy is lost"
HELD_OUT_TITLE = "Where held-out accuracy is lost"
"""The table's title when the query views are held-out views of training scenes."""
REPORT_FILE = "ceilings.json"


def _pct(value: float | None) -> str:
    """A share as a percentage with one decimal, "—" when there is none."""
    return "—" if value is None else f"{100 * value:.1f}"


def ceilings_table(rows: list[dict[str, Any]]) -> str:
    """The Markdown table of a report's rows (oracle rows marked; coverage "—" for per-pixel rows)."""
    header = ["row", "what", "inputs", "oracle", "mIoU %", "total acc %", "coverage %", "acc on covered %",
              "s/view", "budget"]
    body = [[r["key"], r["title"], r["protocol"]["inputs"], "**oracle**" if r["oracle"] else "no", _pct(r["miou"]),
             _pct(r["total_acc"]), _pct(r["coverage"]), _pct(r["acc_on_covered"]),
             "—" if r["seconds_per_view"] is None else f"{r['seconds_per_view']:.3f}", r["budget"] or "—"]
            for r in rows]
    return markdown_table(header, body)


def ceilings_notes(report: dict[str, Any]) -> str:
    """The protocol lines printed under the table."""
    kind = "held-out" if report.get("held_out") else "test"
    views = (f"the first {report['views_per_scene']} {kind} view(s)" if report["views_per_scene"]
             else f"every {kind} view")
    scenes = "training scene(s) (the first by name)" if report.get("held_out") else "unseen test scene(s)"
    return (f"Checkpoint `{report['checkpoint']}` (step {report['checkpoint_step']}), shards `{report['shards']}`: "
            f"{len(report['scenes'])} {scenes}, {views} of each, "
            f"{report['n_source']} fixed sources ({report['source_rule']}). mIoU: dataset-level per scene, "
            f"unweighted mean over scenes; {report['unseen_rule']}. Coverage: labelled query pixels some source "
            f"sees by the row's geometry (occlusion test: relative depth agreement {report['tolerance']}); "
            f"{report['coverage_of_d']}. Votes: {report['tie_rule']}. S-Ray's render (row s, and row c-rgb's "
            f"depth): {report.get('render', 'full')}. Oracle rows read the query view's "
            "ground-truth depth and never sit in a comparison column; e and f rows read the query image, which "
            "S-Ray never sees; row f-src scores the segmenter on the source images themselves (each source view of "
            "a scene once), not on the query. s/view: wall seconds of a row's prediction per view on this machine "
            "(probe fits and segmenter training are in the budget column).")


def run_ceilings(checkpoint: Path, shards: Path, out: Path, doc: Path, *, n_source: int = 8, views_per_scene: int = 0,
                 segmenter: Path | None = None, probe_steps: int = 300, probe_views: int = 64,
                 tolerance: float = 0.05, render: FastRender | None = ZERO_SHOT_RENDER, held_out: int = 0,
                 progress: bool = True) -> dict[str, Any]:
    """Measure, store ``out/ceilings.json``, print and record the table in ``doc``; returns the report.
    ``held_out`` > 0: the query views are the held-out views of that many training scenes (table
    :data:`HELD_OUT_TITLE`)."""
    report = measure_ceilings(checkpoint, shards, n_source=n_source, views_per_scene=views_per_scene,
                              segmenter=segmenter, probe_steps=probe_steps, probe_views=probe_views,
                              tolerance=tolerance, render=render, held_out=held_out, progress=progress)
    path = write_json_atomic(report, Path(out) / REPORT_FILE)
    title = HELD_OUT_TITLE if held_out else TITLE
    record(CEILINGS, title, ceilings_table(report["rows"]), Path(doc), ceilings_notes(report))
    print(f"rows stored in {path}")
    return report
