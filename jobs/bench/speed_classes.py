"""Per-class accounting of ``sray bench speed-accuracy``: IoU in % over every rendered test view (one confusion matrix),
each class's share of labelled pixels, the mean of several checkpoints' rows, the table and the rule's rows."""

from __future__ import annotations

import math

from torch import Tensor

from sray.jobs.bench.render_default import Measured, counted_classes
from sray.model.metrics import scene_metrics
from sray.platform.common.doc_blocks import markdown_table

MEAN_KEYS = ("miou", "psnr", "s_per_view", "wall_s_per_view")


def class_scores(conf: Tensor) -> tuple[list[float | None], list[float]]:
    """Each class's IoU in % (None: absent) and labelled-pixel share of an (L, L) confusion matrix (truth rows)."""
    ious = [None if math.isnan(v) else 100.0 * float(v) for v in scene_metrics(conf)["iou_per_class"]]
    counts = conf.sum(1).double()
    total = float(counts.sum())
    return ious, [float(c) / total if total else 0.0 for c in counts]


def _mean(values: list[float | None]) -> float | None:
    """The mean of ``values``, None when any is None."""
    return None if any(v is None for v in values) else sum(values) / len(values)


def mean_rows(runs: list[list[dict]]) -> list[dict]:
    """Per setting, the mean over ``runs`` (each one checkpoint's ``measure`` rows) of ``MEAN_KEYS`` and of each
    class's IoU (None where a run has none) and share; the rest from the first run, with ``checkpoints``."""
    names = [[r["name"] for r in run] for run in runs]
    if any(n != names[0] for n in names):
        raise ValueError(f"speed-accuracy: the checkpoints' rows name other settings: {names}")
    rows = []
    for per_run in zip(*runs, strict=True):
        row = dict(per_run[0], checkpoints=len(runs))
        row |= {k: sum(r[k] for r in per_run) / len(runs) for k in MEAN_KEYS}
        row["class_iou"] = [_mean(list(v)) for v in zip(*(r["class_iou"] for r in per_run), strict=True)]
        row["class_share"] = [sum(v) / len(runs) for v in zip(*(r["class_share"] for r in per_run), strict=True)]
        rows.append(row)
    return rows


def measured(row: dict) -> Measured:
    """A bench row as the default-render rule reads it (time: CPU seconds per view)."""
    names = row["class_names"]
    return Measured(name=row["name"], miou=row["miou"], seconds=row["s_per_view"],
                    class_iou=dict(zip(names, row["class_iou"], strict=True)),
                    class_share=dict(zip(names, row["class_share"], strict=True)))


def class_table(rows: list[dict], chosen: str | None = None) -> str:
    """Per counted class, its share, then each setting's IoU and its difference to the first row (``chosen`` marked)."""
    ref = measured(rows[0])
    counted = counted_classes(ref)
    lines = [["share of labelled test pixels", *(f"{100 * ref.class_share[c]:.1f}%" for c in counted)]]
    for r in rows:
        m = measured(r)
        name = f"**{m.name}** (chosen)" if m.name == chosen else m.name
        lines.append([name, *(_cell(m.class_iou[c], ref.class_iou[c]) for c in counted)])
    return markdown_table(["IoU % (Δ vs first row, points)", *counted], lines)


def _cell(iou: float | None, ref: float | None) -> str:
    """``45.2 (-1.3)``, or ``-`` for a class absent from the views."""
    if iou is None or ref is None:
        return "-"
    return f"{iou:.1f} ({iou - ref:+.1f})"
