"""Charts of a fleet's results (docs/dashboard.md), a PNG per :data:`FLEET_CHARTS` entry: held-out scores against
time and steps (a panel per scene after their mean; zero-shot step 0 dashed), mIoU against artifact bytes (zero-shot
S-Ray at "0 B"); footnotes name the protocols and results left out. Agg canvas, no pyplot."""

from __future__ import annotations

import logging
import math
import textwrap
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import NullFormatter, NullLocator

from sray.data_tools.atomic import save_png
from sray.model.metrics import DATASET_PROTOCOL
from sray.platform.common.eval_protocol import caption_lines, results_inputs
from sray.platform.viz.chart_style import ChartedMethods
from sray.platform.viz.curves import average_curves, check_result, curve_xy, failure_note, is_chartable, zero_shot_value

log = logging.getLogger(__name__)

METRICS = {"miou": ("held-out mIoU", f"held-out mIoU ({DATASET_PROTOCOL})"),
           "psnr": ("held-out PSNR (dB)", "held-out PSNR (dB, mean over held-out views)")}
"""Curve key -> (axis label, title text)."""
X_AXES = {"wall_s": ("training wall-clock time (s, evaluation excluded)", "wall-clock time"),
          "step": ("optimisation steps", "steps")}
"""Curve key -> (axis label, title text)."""
PANEL_SIZE = (4.8, 3.5)  # inches per panel (width, height)
MIN_WIDTH = 7.0  # narrowest figure (inches), so that a one-panel chart still has room for its legend and footnote
DPI = 110


def _human_bytes(n: float) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n:.0f} B"


def _footnote_parts(ok: list[dict[str, Any]], results: list[dict[str, Any]], extra: str) -> list[str]:
    protocols = caption_lines((r["method"], r.get("protocol")) for r in ok)
    return [p for p in [extra, *protocols, failure_note(results)] if p]


def _framed_figure(width: float, body_height: float, title: str, handles: list[Any],
                   footnote: list[str]) -> tuple[Any, Any]:
    """(figure, body sub-figure for the axes) with a header (title + legend) and a footnote; sizes in inches."""
    ncols = 4 if width >= 12 else 2
    head_h = 0.45 + 0.22 * math.ceil(len(handles) / ncols)
    lines = [line for part in footnote for line in textwrap.wrap(part, max(60, int(width * 17)))]
    foot_h = 0.15 + 0.14 * len(lines)
    fig = Figure(figsize=(width, head_h + body_height + foot_h), dpi=DPI, facecolor="white", layout="constrained")
    FigureCanvasAgg(fig)
    head, body, foot = fig.subfigures(3, 1, height_ratios=[head_h, body_height, foot_h])
    head.text(0.5, 1.0 - 0.08 / head_h, title, ha="center", va="top", fontsize=11, fontweight="bold")
    head.legend(handles=handles, loc="lower center", ncols=ncols, fontsize=8, frameon=False)
    foot.text(0.5, 0.5, "\n".join(lines), ha="center", va="center", fontsize=7, color="#444444")
    return fig, body


def _draw_panel(ax: Any, by_method: dict[str, list[dict[str, Any]]], metric: str, x_key: str, mean: bool,
                methods: ChartedMethods) -> None:
    """One panel: zero-shot lines, then each method's curve (the step-function mean of several)."""
    for method in methods.values():
        zero = [v for r in by_method.get(method.name, []) if (v := zero_shot_value(r, metric, methods)) is not None]
        if zero:
            z = method.zero_shot
            ax.axhline(float(np.mean(zero)), color=z.color, ls="--", lw=1.3, zorder=1)
            ax.plot([0.0], [float(np.mean(zero))], ls="none", marker=z.marker, ms=11, color=z.color, zorder=4,
                    clip_on=False)
    for method in methods.values():
        results = by_method.get(method.name, [])
        curves = [curve_xy(r["curve"], x_key, metric) for r in results]
        x, y = average_curves(curves) if mean else curves[0] if curves else (np.zeros(0), np.zeros(0))
        if not len(x):
            continue
        s = method.style
        ax.step(x, y, where="post", color=s.color, lw=1.8, zorder=3)
        if not mean or len(x) == 1:
            ax.plot(x, y, ls="none", marker=s.marker, ms=4.5, color=s.color, zorder=3)
        if not mean and results[0].get("stopped_early"):
            ax.plot(x[-1:], y[-1:], ls="none", marker="|", ms=16, mew=2.0, color=s.color, zorder=4, clip_on=False)
    ax.grid(True, alpha=0.3)
    ax.set_xlim(left=0.0)
    ax.tick_params(labelsize=8)


def _with_inputs(label: str, ok: list[dict[str, Any]], method: str) -> str:
    """``label`` tagged with the inputs ``method``'s results record in their protocol (``[RGB]``, ``[RGB-D]``)."""
    inputs = results_inputs(ok, method)
    return f"{label} [{inputs}]" if inputs else label


def _legend_handles(ok: list[dict[str, Any]], methods: ChartedMethods) -> list[Any]:
    handles = []
    for method in methods.values():
        if any(r["method"] == method.name and zero_shot_value(r, "miou", methods) is not None for r in ok):
            z = method.zero_shot
            handles.append(Line2D([], [], color=z.color, ls="--", marker=z.marker, ms=9,
                                  label=_with_inputs(z.label, ok, method.name)))
    for method in methods.values():
        if any(r["method"] == method.name for r in ok):
            s = method.style
            handles.append(Line2D([], [], color=s.color, marker=s.marker, ms=5,
                                  label=_with_inputs(s.label, ok, method.name)))
    if any(r.get("stopped_early") for r in ok):
        handles.append(Line2D([], [], color="#555555", ls="none", marker="|", ms=12, mew=2.0,
                              label="finetune stopped early (held-out score stopped improving)"))
    return handles


def curve_figure(results: list[dict[str, Any]], metric: str, x_key: str, methods: ChartedMethods) -> Any:
    """The figure of one (score, x axis) pair: a mean panel (2+ scenes), then one panel per scene."""
    ok = [r for r in results if is_chartable(r)]
    scenes = sorted({r["scene"] for r in ok})
    by_scene = {s: {m: [r for r in ok if r["scene"] == s and r["method"] == m] for m in methods} for s in scenes}
    panels: list[tuple[str, dict[str, list[dict[str, Any]]], bool]] = []
    if len(scenes) >= 2:
        by_method = {m: [r for r in ok if r["method"] == m] for m in methods}
        counts = {methods[m].style.label: len(v) for m, v in by_method.items() if v}
        same = len(set(counts.values())) == 1
        title = (f"mean over {len(scenes)} scenes" if same else
                 "mean over scenes (" + ", ".join(f"{k}: {v}" for k, v in counts.items()) + ")")
        panels.append((title, by_method, True))
    panels += [(f"scene {s}", by_scene[s], False) for s in scenes]
    ncols = min(3, len(panels))
    nrows = math.ceil(len(panels) / ncols)
    y_label, y_title = METRICS[metric]
    x_label, x_title = X_AXES[x_key]
    note = "Curves hold their value between evaluations and after a finetune stops" + (
        "; the mean panel resamples each scene's curve on the union of evaluation points." if len(scenes) >= 2 else ".")
    fig, body = _framed_figure(max(PANEL_SIZE[0] * ncols, MIN_WIDTH), PANEL_SIZE[1] * nrows,
                               f"{y_title} vs {x_title}", _legend_handles(ok, methods),
                               _footnote_parts(ok, results, note))
    axes = body.subplots(nrows, ncols, squeeze=False)
    for ax, (title, by_method, mean) in zip(axes.flat, panels):
        _draw_panel(ax, by_method, metric, x_key, mean, methods)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(x_label, fontsize=8)
        ax.set_ylabel(y_label, fontsize=8)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    return fig


def size_figure(results: list[dict[str, Any]], methods: ChartedMethods) -> Any:
    """mIoU after per-scene optimisation against the per-scene artifact size (log x, '0 B' = zero-shot)."""
    ok = [r for r in results if is_chartable(r)]
    note = ("One point per (scene, method): the best evaluated state, as stored. Dotted: a scene's zero-shot "
            "model -> finetune (S-Ray). Semantic-NeRF stores its whole per-scene model.")
    fig, body = _framed_figure(8.0, 4.6, f"held-out mIoU ({DATASET_PROTOCOL}) vs per-scene artifact size",
                               _legend_handles(ok, methods), _footnote_parts(ok, results, note))
    ax = body.add_subplot()
    sized = [r for r in ok if r.get("artifact_bytes") and r.get("miou_after") is not None]
    full = [float(r["full_checkpoint_bytes"]) for r in ok if r.get("full_checkpoint_bytes")]  # the shared model
    biggest = max([float(r["artifact_bytes"]) for r in sized] + full + [10.0])
    smallest = min([float(r["artifact_bytes"]) for r in sized] + [biggest])
    lo_decade, hi_decade = math.floor(math.log10(smallest)), math.ceil(math.log10(biggest * 1.5))
    x_zero = 10.0 ** (lo_decade - 1)
    zero_labels: dict[float, list[str]] = {}
    for r in sized:
        method = methods[r["method"]]
        x, y = float(r["artifact_bytes"]), float(r["miou_after"])
        ax.plot([x], [y], ls="none", marker=method.style.marker, ms=7, color=method.style.color, zorder=3)
        ax.annotate(r["scene"], (x, y), xytext=(5, 4), textcoords="offset points", fontsize=7, color="#333333")
        zero = zero_shot_value(r, "miou", methods)
        if zero is not None:
            ax.plot([x_zero, x], [zero, y], ls=":", lw=1.0, color="#999999", zorder=2)
            ax.plot([x_zero], [zero], ls="none", marker=method.zero_shot.marker, ms=11, color=method.zero_shot.color,
                    zorder=3)
            zero_labels.setdefault(round(zero, 3), []).append(r["scene"])
    for zero, names in zero_labels.items():  # scenes with the same zero-shot score share one label
        ax.annotate(", ".join(names), (x_zero, zero), xytext=(7, -3), textcoords="offset points", fontsize=7,
                    color="#333333")
    if full:
        ax.axvline(float(np.median(full)), color="#555555", ls="--", lw=1.0)
        ax.annotate(f"full S-Ray checkpoint\n{_human_bytes(float(np.median(full)))}", (float(np.median(full)), 0.02),
                    xycoords=("data", "axes fraction"), xytext=(-6, 0), textcoords="offset points", ha="right",
                    fontsize=7, color="#555555")
    ax.set_xscale("log")
    ax.set_xlim(x_zero / 3.0, 10.0 ** hi_decade)
    ax.axvspan(x_zero * 2.0, 10.0 ** lo_decade / 2.0, color="#eeeeee", zorder=0)  # the axis break
    ticks = [x_zero] + [10.0 ** k for k in range(lo_decade, hi_decade + 1)]
    ax.set_xticks(ticks, ["0 B\n(zero-shot)"] + [_human_bytes(t) for t in ticks[1:]], fontsize=8)
    ax.xaxis.set_minor_locator(NullLocator())
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("per-scene artifact size (bytes stored besides the shared model; log scale)", fontsize=9)
    ax.set_ylabel("held-out mIoU (best evaluated state)", fontsize=9)
    return fig


FleetChart = Callable[[list[dict[str, Any]], ChartedMethods], Any]
"""``chart(results, methods) -> matplotlib Figure`` of a fleet's results (failed ones included, to name them)."""

FLEET_CHARTS: dict[str, FleetChart] = {
    **{f"{metric}_vs_{x_key}": partial(lambda results, methods, m, x: curve_figure(results, m, x, methods),
                                       m=metric, x=x_key) for metric in METRICS for x_key in X_AXES},
    "miou_vs_artifact_bytes": size_figure,
}
"""Every chart a fleet writes, by file stem (``<stem>.png``): add an entry to add a chart."""


def write_fleet_charts(results: list[dict[str, Any]], out_dir: Path, methods: ChartedMethods) -> list[Path]:
    """Write every chart of :data:`FLEET_CHARTS` as ``<out_dir>/<stem>.png`` (atomically) and return the paths;
    ``methods`` in legend order. With no finished result nothing is written (a warning says so)."""
    for r in results:
        check_result(r, methods)
    if not any(is_chartable(r) for r in results):
        log.warning("no finished fleet result with an evaluated point: no charts written to %s", out_dir)
        return []
    out_dir = Path(out_dir)
    return [save_png(chart(results, methods), out_dir / f"{stem}.png", DPI) for stem, chart in FLEET_CHARTS.items()]
