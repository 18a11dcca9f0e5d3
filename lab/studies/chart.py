"""A study's chart: each arm's mean mIoU with its seed spread, per split, beside its seeds' own values."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png
from sray.lab.studies.paired import by_arm_and_seed, mean_and_std

SPLIT_LABELS = {"zero_shot": "test rooms (zero-shot)", "zero_shot_appearance": "appearance-shifted test rooms",
                "zero_shot_geometry": "geometry-shifted test rooms", "validation": "validation rooms",
                "held_out": "held-out views of training rooms",
                "fleet.sray": "test rooms after a per-room S-Ray finetune"}
"""How the chart and the page name each split."""


def miou_chart(results: dict[str, dict[str, Any]], arms: list[str], path: Path, title: str) -> Path | None:
    """Bars of each arm's mean mIoU (error bar: the seeds' sample standard deviation) per split, and a dot per seed;
    written to ``path`` (PNG). None when no result holds an mIoU."""
    splits = [s for s in SPLIT_LABELS if by_arm_and_seed(results, s)]
    if not splits:
        return None
    fig = Figure(figsize=(max(6.0, 0.9 * len(arms) * len(splits) + 2), 4.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    width = 0.8 / len(splits)
    for j, split in enumerate(splits):
        table = by_arm_and_seed(results, split)
        label: str | None = SPLIT_LABELS[split]
        for i, arm in enumerate(arms):
            values = list(table.get(arm, {}).values())
            mean, std = mean_and_std(values)
            if mean is None:
                continue
            x = i + (j - (len(splits) - 1) / 2) * width
            ax.bar(x, mean, width * 0.9, yerr=std or 0.0, capsize=3, color=f"C{j}", label=label)
            label = None  # one legend entry per split
            ax.plot([x] * len(values), values, "k.", markersize=4)
    ax.set_xticks(range(len(arms)), arms, rotation=30, ha="right")
    ax.set_ylabel("mIoU %")
    ax.set_title(title)
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return save_png(fig, path, dpi=110)
