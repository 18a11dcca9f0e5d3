"""A chart of scores over training seeds: one column per row label, every seed a dot, the mean a bar
with its sample standard deviation (the seed spread the ablation tables quote)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png


def write_seed_chart(values: dict[str, list[float]], y_label: str, title: str, footnote: str, path: Path) -> Path:
    """Draw ``values`` (row label -> one score per seed, in column order) and write the PNG to ``path``.

    A row with two or more seeds gets a standard-deviation error bar; every seed is drawn as a dot.
    ValueError when no row has a value.
    """
    rows = {label: v for label, v in values.items() if v}
    if not rows:
        raise ValueError(f"{path}: no scores to chart")
    width = max(4.5, 1.1 * len(rows) + 2.0)
    fig = Figure(figsize=(width, 4.2))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.12, 0.2, 0.84, 0.68))
    for x, (label, scores) in enumerate(rows.items()):
        mean = float(np.mean(scores))
        spread = float(np.std(scores, ddof=1)) if len(scores) > 1 else 0.0
        ax.bar(x, mean, width=0.6, color="#9ecae1", edgecolor="#3182bd",
               yerr=spread if len(scores) > 1 else None, capsize=5)
        ax.scatter(np.full(len(scores), x, dtype=float) + np.linspace(-0.12, 0.12, len(scores)), scores,
                   color="#08306b", s=18, zorder=3)
    ax.set_xticks(range(len(rows)), [f"{label}\n({len(v)} seed{'s' if len(v) > 1 else ''})"
                                     for label, v in rows.items()])
    ax.set_ylabel(y_label)
    ax.grid(axis="y", alpha=0.3)
    fig.suptitle("\n".join(textwrap.wrap(title, int(width * 13))), fontsize=9)
    fig.text(0.01, 0.01, "\n".join(textwrap.wrap(footnote, int(width * 16))), fontsize=6.5, va="bottom")
    return save_png(fig, path, dpi=120)
