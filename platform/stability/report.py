"""What a stability run leaves: ``stability.json``, the chart of each score, a table per axis, the
breaking points, and the tracked runs (a parent run, a child run per axis).

Scores are the dataset-level mIoU (%) and PSNR (dB) of the held-out views, averaged over scenes;
each table and chart carries the evaluation protocol of the S-Ray points and says how Semantic-NeRF
was scored.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json, atomic_write_text
from sray.platform.finetune.methods.registry import get_method
from sray.platform.stability.axes import AXES
from sray.platform.stability.presets import Preset
from sray.platform.stability.summary import LevelStats, axis_table, breaking_summary, level_stats
from sray.platform.tracking.tracker import Tracker
from sray.platform.viz.chart_style import ChartStyle
from sray.platform.viz.stability_chart import LevelPoint, StabilityPanel, write_stability_chart

RESULTS_FILE = "stability.json"
"""Every point record of the run, its preset, protocol and breaking points, under the run's folder."""


def method_styles() -> dict[str, ChartStyle]:
    """How each method of the suite is drawn (colours of the fleet's methods, S-Ray without CRA in green)."""
    sray, nerf = get_method("sray").style, get_method("semantic-nerf").style
    return {"sray": ChartStyle("S-Ray, full CRA (zero-shot)", sray.color, sray.marker),
            "sray-no-cra": ChartStyle("S-Ray without CRA (zero-shot)", "#2ca02c", "^"),
            "semantic-nerf": ChartStyle(nerf.label, nerf.color, nerf.marker)}


def panels(stats: list[LevelStats], axes: list[str], metric: str) -> list[StabilityPanel]:
    """One chart panel per axis of ``metric`` (``miou`` or ``psnr``)."""
    out = []
    for axis in axes:
        rows = [s for s in stats if s.axis == axis]
        levels = [s.level for s in rows]
        harmless_high = not isinstance(levels[0], str) and len(levels) > 1 and levels[0] > levels[-1]
        panel = StabilityPanel(axis.replace("_", " "), AXES[axis].unit, log_x=axis == "source_views",
                               harmless_high=harmless_high)
        for s in rows:
            mean, low, high = ((s.miou_mean, s.miou_min, s.miou_max) if metric == "miou"
                               else (s.psnr_mean, s.psnr_min, s.psnr_max))
            x = s.level if isinstance(s.level, str) or s.x is None else s.x
            panel.lines.setdefault(s.method, []).append(LevelPoint(x, mean, low, high))
        out.append(panel)
    return out


def notes(preset: Preset, protocol_line: str) -> list[str]:
    """The lines every table and chart of the run carries."""
    return [f"S-Ray points — {protocol_line}.",
            f"Semantic-NeRF — trained from scratch per point on the first {preset.nerf_scenes} test scene(s), at most "
            f"{preset.nerf_steps} steps / {preset.nerf_seconds:g} s of training, {preset.nerf_rays} rays a step, "
            "scored on the same held-out views (stride and chunk as S-Ray).",
            f"Every perturbed point: mean over {preset.seeds} perturbation seeds, band = min-max; points that draw "
            "nothing at random (clean, source-view choice, precision) are computed once. One pretraining seed per "
            "S-Ray variant."]


def precision_table(records: list[dict[str, Any]]) -> str:
    """Non-finite rays and argmax agreement with fp32, per method and precision."""
    rows = ["| method | precision | non-finite rays | argmax agreement with fp32 | status |", "|---|---|---|---|---|"]
    for r in records:
        if r["axis"] == "precision":
            agree = r.get("fp32_agreement")
            rows.append(f"| {r['method']} | {r['level']} | {r.get('nonfinite_rays', '-')} | "
                        f"{'-' if agree is None else f'{100 * agree:.2f} %'} | {r['status']} |")
    return "\n".join(rows)


def write_outputs(records: list[dict[str, Any]], preset: Preset, axes: list[str], protocol_line: str,
                  out_dir: Path, extra: dict[str, Any]) -> dict[str, Any]:
    """Write ``stability.json``, the two charts and one Markdown table per axis under ``out_dir``.

    Returns ``{"tables": {axis: markdown}, "charts": [png paths], "breaking": [lines], "json": path}``.
    """
    stats = level_stats(records)
    styles = method_styles()
    lines = notes(preset, protocol_line)
    title = f"Where the methods break — sray stability --preset {preset.name}"
    charts = [write_stability_chart(panels(stats, axes, metric), styles, label, f"{title}: {name}\n{protocol_line}",
                                    lines[1:], out_dir / f"stability_{metric}.png")
              for metric, name, label in (("miou", "mIoU", "mIoU (%)"), ("psnr", "PSNR", "PSNR (dB)"))]
    tables = {}
    for axis in axes:
        table = axis_table(stats, axis, AXES[axis].unit)
        if axis == "precision":
            table += "\n\n" + precision_table(records)
        if axis == "unseen_rays":
            fractions = {s.level: s.x for s in stats if s.axis == axis and s.x is not None}
            table += "\n\nMeasured fraction of coarse samples no source view sees, per level: " + ", ".join(
                f"{lvl} → {100 * x:.1f} %" for lvl, x in fractions.items())
        tables[axis] = table
        atomic_write_text(out_dir / "tables" / f"{axis}.md", table + "\n")
    breaking = breaking_summary(stats, axes)
    path = out_dir / RESULTS_FILE
    atomic_write_json(path, {"preset": preset.name, "axes": axes, "protocol": protocol_line, "notes": lines,
                             "breaking_points": breaking, **extra, "points": records,
                             "stats": [dataclasses.asdict(s) for s in stats]})
    return {"tables": tables, "charts": charts, "breaking": breaking, "json": path, "notes": lines}


def track(tracker: Tracker, experiment: str, run_name: str, outputs: dict[str, Any],
          records: list[dict[str, Any]], axes: list[str], preset: Preset) -> str:
    """Log the run: a parent run (the charts, stability.json, breaking points) and a child run per axis
    (its table, and ``<method>/miou`` and ``<method>/psnr`` at step = level index). Returns the parent run id."""
    parent = tracker.start_run(experiment, run_name, tags={"sray.kind": "stability", "sray.preset": preset.name})
    with tracker.logger(parent) as log:
        log.log_params({"preset": preset.name, "axes": axes, "seeds": preset.seeds, "levels": preset.levels})
        for chart in outputs["charts"]:
            log.log_image(chart, "charts")
        log.log_artifact(outputs["json"])
        for axis in axes:
            child = tracker.start_run(experiment, f"{run_name}/{axis}", parent=parent,
                                      tags={"sray.kind": "stability-axis", "sray.axis": axis})
            with tracker.logger(child) as axis_log:
                axis_log.log_params({"axis": axis, "unit": AXES[axis].unit, "levels": list(preset.levels[axis])})
                for stat in (s for s in level_stats(records) if s.axis == axis):
                    step = list(preset.levels[axis]).index(stat.level)
                    values = {f"{stat.method}/miou": stat.miou_mean, f"{stat.method}/psnr": stat.psnr_mean,
                              f"{stat.method}/failed_seeds": stat.n_failed}
                    axis_log.log_metrics({k: v for k, v in values.items() if v is not None}, step)
                axis_log.log_artifact(outputs["json"].parent / "tables" / f"{axis}.md", "tables")
    return parent.run_id
