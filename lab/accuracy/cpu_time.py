"""Accuracy against pretraining CPU time: the cells of ``sray lab accuracy`` grouped into arms (cells whose
model and data settings are equal, whatever their budget), one point per budget with its seed range, as a
table and a chart of zero-shot and held-out training-scene mIoU against CPU hours."""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png
from sray.lab.accuracy.plan import HOUR, HOUR_INTRA_UNCAPPED, LONG, VARIANT_SETTINGS, Preset
from sray.lab.accuracy.variant import Variant

BUDGET_VARIANTS = (LONG, HOUR, HOUR_INTRA_UNCAPPED)
"""Variants that only change the budget of another variant's settings (they join that variant's arm); a variant with
its own CPU budget (``Variant.cpu_seconds``: the screening cells) also joins an arm of equal settings when there is
one."""


def arm_of(variant: str) -> str:
    """The arm of ``variant``: the first variant with the same settings, its step cap and CPU budget aside, variants
    with their own CPU budget next to last and budget variants last (``hour-intra-uncapped`` and ``screen`` join
    ``hour-intra``, a screened lever its hour arm: ``screen-lr-rays`` joins ``hour-lr-rays``; a screened lever without
    an hour arm, such as ``screen-occl``, is its own arm)."""
    def uncapped(name: str) -> Variant:
        return replace(VARIANT_SETTINGS[name], step_cap=None, cpu_seconds=None)

    def rank(name: str) -> tuple[bool, bool]:
        return name in BUDGET_VARIANTS, VARIANT_SETTINGS[name].cpu_seconds is not None

    ordered = sorted(VARIANT_SETTINGS, key=rank)  # stable: VARIANT_SETTINGS order within a rank
    return next(v for v in ordered if uncapped(v) == uncapped(variant))


@dataclass(frozen=True)
class BudgetPoint:
    """The cells of one arm trained for one budget (one variant): per-seed CPU hours and scores."""

    arm: str
    variant: str
    rooms: int
    """Training rooms of the arm's world."""
    cpu_hours: list[float]
    zero_shot: list[float]
    """Zero-shot mIoU %, one per seed."""
    held_out: list[float | None]
    """Held-out training-scene mIoU %, one per seed (None for a cell that did not measure it)."""

    def seeds_of(self, field: str) -> tuple[list[float], list[float]]:
        """(CPU hours, scores) of the seeds that hold ``field`` (``zero_shot`` or ``held_out``)."""
        pairs = [(h, v) for h, v in zip(self.cpu_hours, getattr(self, field), strict=True) if v is not None]
        return [h for h, _ in pairs], [v for _, v in pairs]


def budget_points(p: Preset, stored: dict[str, dict[str, Any]]) -> tuple[list[BudgetPoint], list[str]]:
    """Each (arm, variant) of the stored cells with their CPU hours and scores, in plan order; and the keys of
    stored cells left out because they carry no CPU time (stored before it was recorded)."""
    grouped: dict[str, list[dict[str, Any]]] = {}
    untimed = []
    for cell in p.plan:
        record = stored.get(cell.key)
        if record is None:
            continue
        if record.get("train_cpu_s") is None:
            untimed.append(cell.key)
            continue
        grouped.setdefault(cell.variant, []).append(record)
    points = [BudgetPoint(arm=arm_of(variant), variant=variant,
                          rooms=VARIANT_SETTINGS[variant].train_scenes or p.world.train_scenes,
                          cpu_hours=[c["train_cpu_s"] / 3600.0 for c in cells],
                          zero_shot=[100.0 * c["miou"] for c in cells],
                          held_out=[None if c.get("heldout_miou") is None else 100.0 * c["heldout_miou"]
                                    for c in cells])
              for variant, cells in grouped.items()]
    return points, untimed


def _cell(values: list[float]) -> str:
    """Mean ± sample standard deviation (mean alone for one value, a dash for none)."""
    if not values:
        return "—"
    if len(values) == 1:
        return f"{values[0]:.2f}"
    return f"{np.mean(values):.2f} ± {np.std(values, ddof=1):.2f}"


def cpu_time_rows(points: list[BudgetPoint]) -> tuple[list[str], list[list[str]]]:
    """The table of ``points``: arm, budget (variant), training rooms, seeds, CPU hours, zero-shot and held-out
    mIoU."""
    header = ["arm", "cell (budget)", "training rooms", "seeds", "pretrain CPU h", "zero-shot mIoU %",
              "held-out train-scene mIoU %"]
    rows = [[pt.arm, pt.variant, str(pt.rooms), str(len(pt.zero_shot)), f"{np.mean(pt.cpu_hours):.2f}",
             _cell(pt.zero_shot),
             _cell(pt.seeds_of("held_out")[1])] for pt in points]
    return header, rows


def cpu_time_chart(points: list[BudgetPoint], path: Path, title: str, caption: str) -> Path:
    """Zero-shot (left) and held-out training-scene (right) mIoU against pretraining CPU hours: one line per
    arm through its budgets' means, a band over its seeds' range, every seed a dot. ValueError without
    points."""
    if not points:
        raise ValueError(f"{path}: no cells with a CPU time to chart")
    fig = Figure(figsize=(10, 4.8))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2, sharex=True)
    arms = list(dict.fromkeys(pt.arm for pt in points))
    colours = {arm: f"C{i % 10}" for i, arm in enumerate(arms)}
    for ax, field, label in ((axes[0], "zero_shot", "zero-shot mIoU % (unseen scenes)"),
                             (axes[1], "held_out", "held-out training-scene mIoU %")):
        for arm in arms:
            seeds = sorted((pt.seeds_of(field) for pt in points if pt.arm == arm and pt.seeds_of(field)[1]),
                           key=lambda hs: float(np.mean(hs[0])))
            if not seeds:
                continue
            xs = [float(np.mean(hours)) for hours, _ in seeds]
            most = max(len(scores) for _, scores in seeds)
            ax.plot(xs, [float(np.mean(scores)) for _, scores in seeds], "-o", color=colours[arm],
                    label=f"{arm} (up to {most} seed{'s' * (most > 1)})")
            ax.fill_between(xs, [min(scores) for _, scores in seeds], [max(scores) for _, scores in seeds],
                            color=colours[arm], alpha=0.2)
            for hours, scores in seeds:
                ax.scatter(hours, scores, color=colours[arm], s=10, alpha=0.7)
        ax.set_xlabel("pretraining CPU hours (ranks + loader processes)")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(title + "\n" + "\n".join(textwrap.wrap(caption, 150)), fontsize=7)
    fig.tight_layout()
    return save_png(fig, path, dpi=120)
