"""The stability suite's chart (PNG): one panel per stress axis (:class:`StabilityPanel`, made by the caller), a
score against the axis's level, one line per method with its seed spread (min-max band), failed levels marked."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png
from sray.platform.viz.chart_style import ChartStyle

PANEL_SIZE = (4.2, 3.2)  # inches per panel (width, height)
COLUMNS = 3  # panels per row
FAILED_COLOR = "#d62728"  # colour of the marks of failed levels
DPI = 110
LEGEND_CHARS_PER_INCH = 15
"""About how many legend characters (9 pt) fit in an inch: legends of long labels get fewer columns."""
LEGEND_ROW_INCHES = 0.22  # height of one legend row


@dataclass(frozen=True)
class LevelPoint:
    """One method at one level: x (a number or a category), mean over seeds (None: all failed), their spread."""

    x: float | str
    mean: float | None
    low: float | None = None
    high: float | None = None


@dataclass
class StabilityPanel:
    """One axis: title, x label, points per method in level order; ``log_x``: log-2 x (counts of views);
    ``harmless_high``: x drawn decreasing (views, JPEG quality), so every panel reads harmless (left) to broken."""

    title: str
    x_label: str
    lines: dict[str, list[LevelPoint]] = field(default_factory=dict)
    log_x: bool = False
    harmless_high: bool = False


def _positions(panel: StabilityPanel) -> tuple[dict[float | str, float], list[str] | None]:
    """x value -> drawn position; category names when the axis is categorical."""
    xs = list(dict.fromkeys(p.x for pts in panel.lines.values() for p in pts))
    if any(isinstance(x, str) for x in xs):
        return {x: float(i) for i, x in enumerate(xs)}, [str(x) for x in xs]
    return {x: float(x) for x in xs}, None


def write_stability_chart(panels: list[StabilityPanel], styles: Mapping[str, ChartStyle], y_label: str, title: str,
                          footnote: list[str], path: Path) -> Path:
    """Draw ``panels`` (a failed level: a red x at the bottom) into the PNG ``path``; ``title``: name, then protocol."""
    rows = math.ceil(len(panels) / COLUMNS)
    width = PANEL_SIZE[0] * min(COLUMNS, len(panels))
    lines = [ln for part in footnote for ln in textwrap.wrap(part, max(60, int(width * 17)))]
    title_lines = [ln for part in title.split("\n") for ln in textwrap.wrap(part, int(width * 14))]
    labels = [styles[m].label for panel in panels for m in panel.lines]
    longest = max((len(label) for label in labels), default=0)
    columns = max(1, min(4, len(set(labels)) + 1, int(width // (longest / LEGEND_CHARS_PER_INCH + 0.7))))
    legend_rows = math.ceil((len(set(labels)) + 1) / columns)  # + the failed-level mark
    head = 0.8 + 0.2 * len(title_lines) + LEGEND_ROW_INCHES * legend_rows
    foot = 0.2 + 0.16 * len(lines)
    height = PANEL_SIZE[1] * rows + head + foot
    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(rows, min(COLUMNS, len(panels)), top=1 - head / height, bottom=foot / height + 0.06,
                            hspace=0.55, wspace=0.3)
    handles: dict[str, object] = {}
    for k, panel in enumerate(panels):
        ax = fig.add_subplot(grid[k // COLUMNS, k % COLUMNS])
        pos, categories = _positions(panel)
        for method, points in panel.lines.items():
            style = styles[method]
            ok = [p for p in points if p.mean is not None]
            xs = [pos[p.x] for p in ok]
            (line,) = ax.plot(xs, [p.mean for p in ok], color=style.color, marker=style.marker, label=style.label)
            handles.setdefault(style.label, line)
            if ok and all(p.low is not None for p in ok):
                ax.fill_between(xs, [p.low for p in ok], [p.high for p in ok], color=style.color, alpha=0.18,
                                linewidth=0)
            failed = [pos[p.x] for p in points if p.mean is None]
            if failed:
                mark = ax.scatter(failed, [0.0] * len(failed), color=FAILED_COLOR, marker="x", s=60, zorder=5,
                                  label="failed (every seed)")
                handles.setdefault("failed (every seed)", mark)
        if categories is not None:
            ax.set_xticks(range(len(categories)), categories)
        elif panel.log_x:
            ax.set_xscale("log", base=2)
        if panel.harmless_high:
            ax.invert_xaxis()
        ax.set_title(panel.title, fontsize=10)
        ax.set_xlabel(textwrap.fill(panel.x_label, 45), fontsize=8)
        ax.set_ylabel(y_label, fontsize=8)
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
    fig.text(0.5, 1 - 0.1 / height, title_lines[0], fontsize=12, ha="center", va="top")
    fig.text(0.5, 1 - 0.38 / height, "\n".join(title_lines[1:]), fontsize=8, ha="center", va="top")
    fig.legend(list(handles.values()), list(handles), loc="upper center", ncols=min(columns, len(handles)),
               bbox_to_anchor=(0.5, 1 - (0.3 + 0.2 * len(title_lines)) / height), fontsize=9, frameon=False)
    fig.text(0.01, 0.01, "\n".join(lines), fontsize=7, va="bottom", ha="left")
    return save_png(fig, path, DPI)
