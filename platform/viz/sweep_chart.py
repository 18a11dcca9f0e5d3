"""A sweep's chart: the metric against each trial's running time, one line per trial, the best one thickest;
its end marks how the trial ended (:data:`ENDS`: a large cross where the scheduler stopped it early)."""

from __future__ import annotations

import textwrap
from dataclasses import dataclass
from pathlib import Path

from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png

ENDS = {"finished": ("o", "-", ""), "stopped": ("X", "-", " (stopped early)"),
        "errored": ("x", ":", " (errored)"), "unfinished": (">", ":", " (unfinished)")}
"""Reason a trial ended -> (end marker, line style, legend suffix)."""
DPI = 110


@dataclass(frozen=True)
class TrialCurve:
    """One trial's line: legend (key, values), running time (s) and metric per report, its end (key of :data:`ENDS`)."""

    label: str
    time_s: list[float]
    values: list[float]
    reason: str


def write_sweep_chart(curves: list[TrialCurve], metric: str, title: str, footnote: str, path: Path,
                      best: str | None = None) -> Path:
    """Draw the curves (``best``: the best trial's label) into the PNG ``path``; ValueError when none has a point."""
    drawn = [c for c in curves if c.values]
    if not drawn:
        raise ValueError(f"{path}: no trial reported {metric}; nothing to chart")
    fig = Figure(figsize=(8.5, 4.8), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    colours = colormaps["tab10"].colors
    for i, curve in enumerate(drawn):
        marker, style, suffix = ENDS[curve.reason]
        colour = colours[i % len(colours)]
        width = 2.8 if curve.label == best else 1.5
        ax.plot(curve.time_s, curve.values, ls=style, lw=width, color=colour, marker=".", ms=4,
                label=curve.label + suffix)
        ax.plot(curve.time_s[-1:], curve.values[-1:], ls="none", marker=marker, color=colour,
                ms=13 if curve.reason == "stopped" else 7, mec="black" if curve.reason == "stopped" else colour,
                zorder=4)
    ax.set_xlabel("trial running time (s)")
    ax.set_ylabel(metric)
    ax.set_xlim(left=0.0)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    ax.set_title("\n".join(textwrap.wrap(title, 80)), fontsize=10)
    fig.supxlabel("\n".join(textwrap.wrap(footnote, 150)), fontsize=6.5, color="#444444", x=0.01, ha="left")
    return save_png(fig, path, DPI)
