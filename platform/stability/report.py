"""What a stability run leaves (docs/stability.md, "Outputs"): stats, breaking points, charts, tables, runs."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json, atomic_write_text
from sray.platform.common.eval_protocol import EvalProtocol, caption_lines
from sray.platform.finetune.methods.registry import get_method
from sray.platform.stability.axes import AXES, Preset
from sray.platform.stability.rows import VARIANT_WORDS, Row
from sray.platform.tracking.tracker import Tracker
from sray.platform.viz.stability_chart import LevelPoint, StabilityPanel, write_stability_chart

RESULTS_FILE = "stability.json"
"""Every point record of the run, its preset, protocols and breaking points, under the run's folder."""


@dataclass(frozen=True)
class LevelStats:
    """One (axis, method, level) over its seeds."""

    axis: str
    method: str
    level: Any
    x: float | None
    """Mean chart x over the ok seeds (None when every seed failed, or on a categorical axis)."""
    miou_mean: float | None
    miou_min: float | None
    miou_max: float | None
    psnr_mean: float | None
    n_ok: int
    n_failed: int
    psnr_min: float | None = None
    psnr_max: float | None = None


def _mean(values: list[float]) -> float | None:
    return sum(values) / len(values) if values else None


def level_stats(points: list[dict[str, Any]]) -> list[LevelStats]:
    """Group points by (axis, method, level), in first-seen order, with mean / min / max over seeds."""
    groups: dict[tuple[str, str, Any], list[dict[str, Any]]] = {}
    for p in points:
        groups.setdefault((p["axis"], p["method"], p["level"]), []).append(p)
    out = []
    for (axis, method, level), group in groups.items():
        ok = [p for p in group if p["status"] == "ok"]
        mious = [float(p["miou"]) for p in ok]
        psnrs = [float(p["psnr"]) for p in ok if p.get("psnr") is not None]
        out.append(LevelStats(axis, method, level,
                              _mean([float(p["x"]) for p in ok if isinstance(p.get("x"), (int, float))]),
                              _mean(mious), min(mious, default=None), max(mious, default=None), _mean(psnrs),
                              len(ok), len(group) - len(ok), min(psnrs, default=None), max(psnrs, default=None)))
    return out


def breaking_point(stats: list[LevelStats]) -> tuple[Any, str]:
    """(The level where one method on one axis loses half its clean mIoU, None if it never does; how it was found),
    from stats in level order (the first clean); interpolated between numeric levels, all-failed levels count 0."""
    if not stats or stats[0].miou_mean is None:
        return None, "no clean score (the clean level failed)"
    clean = stats[0].miou_mean
    half = clean / 2
    prev_level, prev_value = stats[0].level, clean
    for s in stats[1:]:
        value = 0.0 if s.miou_mean is None else s.miou_mean
        if value <= half:
            if isinstance(s.level, str) or isinstance(prev_level, str) or math.isclose(prev_value, value):
                return s.level, "first level at or below half"
            t = (prev_value - half) / (prev_value - value)
            return prev_level + t * (s.level - prev_level), "interpolated between levels"
        prev_level, prev_value = s.level, value
    return None, f"mIoU stays above {half:.1f}, half of the clean {clean:.1f}"


def _fmt(v: float | None, digits: int = 2) -> str:
    return "failed" if v is None else f"{v:.{digits}f}"


def axis_table(stats: list[LevelStats], axis: str, unit: str, headers: dict[str, str] | None = None) -> str:
    """Markdown table of one axis: a row per level, a column pair per method (``headers[method]``, default its name)."""
    rows = [s for s in stats if s.axis == axis]
    methods = list(dict.fromkeys(s.method for s in rows))
    levels = list(dict.fromkeys(s.level for s in rows))
    by = {(s.method, s.level): s for s in rows}
    names = {m: (headers or {}).get(m, m) for m in methods}
    head = f"| {unit} | " + " | ".join(f"{names[m]} mIoU % (min-max) | {names[m]} PSNR dB" for m in methods) + " |"
    lines = [head, "|" + "---|" * (1 + 2 * len(methods))]
    for level in levels:
        cells = []
        for m in methods:
            s = by.get((m, level))
            if s is None:
                cells += ["-", "-"]
                continue
            spread = "" if s.miou_mean is None else f" ({_fmt(s.miou_min, 1)}-{_fmt(s.miou_max, 1)})"
            failed = f", {s.n_failed} failed" if s.n_failed and s.n_ok else ""
            cells += [f"{_fmt(s.miou_mean)}{spread}{failed}", _fmt(s.psnr_mean)]
        lines.append(f"| {level} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def breaking_summary(stats: list[LevelStats], axes: list[str]) -> list[str]:
    """One line per (axis, method): the level at which it loses half its clean mIoU."""
    lines = []
    for axis in axes:
        rows = [s for s in stats if s.axis == axis]
        for method in dict.fromkeys(s.method for s in rows):
            level, how = breaking_point([s for s in rows if s.method == method])
            if level is None:
                lines.append(f"{axis} / {method}: keeps half its clean mIoU at every level tested ({how})")
                continue
            where = (f"{level:.3g}" if isinstance(level, float) else str(level)) + f" ({how})"
            lines.append(f"{axis} / {method}: half the clean mIoU lost at {where}")
    return lines


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


def seen_line(preset: Preset, rows: list[Row]) -> str:
    """The chart's subtitle: which rows saw the scene, and the trained rows' one budget."""
    trained = (f"; rows trained on the scene had {preset.scene_cpu_seconds:g} CPU seconds of training on each, the "
               "same for every method") if any(r.trained for r in rows) else ""
    return "Zero-shot rows never saw the test scenes" + trained


def notes(preset: Preset, rows: list[Row], protocols: dict[str, EvalProtocol]) -> list[str]:
    """The lines every table and chart carries: each row's protocol, how the trained rows were trained, the seeds."""
    lines = caption_lines([(r.name, protocols[r.name].to_json()) for r in rows])
    trained = [r for r in rows if r.trained]
    if trained:
        rays = f"{preset.scene_rays} rays" if preset.scene_rays else "the checkpoint's rays"
        lines.append(f"Trained on the scene — per point, each method's fleet learner trained on the first "
                     f"{preset.trained_scenes} test scene(s) for {preset.scene_cpu_seconds:g} CPU seconds of training "
                     f"steps (time.process_time; one budget for every method), {rays} a step, then scored on the same "
                     "held-out views (stride and chunk as zero-shot; no early stopping): "
                     + "; ".join(f"{r.name}: {get_method(r.method).summary}{VARIANT_WORDS[r.variant]}"
                                 for r in trained) + ".")
    if any(not r.trained for r in rows):
        lines.append("Zero-shot — pretrained models, never trained on the test scenes, scored on every test scene.")
    lines.append(f"Every perturbed point and every point of a trained row: mean over {preset.seeds} seeds, band = "
                 "min-max; zero-shot points that draw nothing at random (clean, source-view choice, precision) are "
                 "computed once. One pretraining seed per pretrained model.")
    return lines


def precision_table(records: list[dict[str, Any]]) -> str:
    """Non-finite rays and argmax agreement with fp32, per method and precision."""
    rows = ["| method | precision | non-finite rays | argmax agreement with fp32 | status |", "|---|---|---|---|---|"]
    for r in records:
        if r["axis"] == "precision":
            agree = r.get("fp32_agreement")
            rows.append(f"| {r['method']} | {r['level']} | {r.get('nonfinite_rays', '-')} | "
                        f"{'-' if agree is None else f'{100 * agree:.2f} %'} | {r['status']} |")
    return "\n".join(rows)


def write_outputs(records: list[dict[str, Any]], preset: Preset, axes: list[str], rows: list[Row],
                  protocols: dict[str, EvalProtocol], out_dir: Path, extra: dict[str, Any]) -> dict[str, Any]:
    """Write ``stability.json``, the two charts and one Markdown table per axis under ``out_dir``; ``protocols``: row
    name -> how its scores were made. ``{"tables": {axis: md}, "charts", "breaking", "json": path, "notes"}``."""
    stats = level_stats(records)
    styles = {r.name: r.style(protocols[r.name]) for r in rows}
    headers = {r.name: r.header for r in rows}
    lines = notes(preset, rows, protocols)
    title = f"Where the methods break — sray stability --preset {preset.name}"
    charts = [write_stability_chart(panels(stats, axes, metric), styles, label,
                                    f"{title}: {name}\n{seen_line(preset, rows)}", lines,
                                    out_dir / f"stability_{metric}.png")
              for metric, name, label in (("miou", "mIoU", "mIoU (%)"), ("psnr", "PSNR", "PSNR (dB)"))]
    tables = {}
    for axis in axes:
        table = axis_table(stats, axis, AXES[axis].unit, headers)
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
    atomic_write_json(path, {"preset": preset.name, "axes": axes, "notes": lines, "breaking_points": breaking,
                             "rows": [{**dataclasses.asdict(r), "header": r.header, "label": styles[r.name].label,
                                       "protocol": protocols[r.name].to_json()} for r in rows],
                             **extra, "points": records, "stats": [dataclasses.asdict(s) for s in stats]})
    return {"tables": tables, "charts": charts, "breaking": breaking, "json": path, "notes": lines}


def track(tracker: Tracker, experiment: str, run_name: str, outputs: dict[str, Any],
          records: list[dict[str, Any]], axes: list[str], preset: Preset) -> str:
    """Log a parent run (charts, stability.json) and a child per axis (its table, metrics at step = level index)."""
    parent = tracker.start_run(experiment, run_name, tags={"sray.kind": "stability", "sray.preset": preset.name})
    with tracker.logger(parent) as log:
        log.log_params({"preset": preset.name, "axes": axes, "seeds": preset.seeds, "levels": preset.levels,
                        "scene_cpu_seconds": preset.scene_cpu_seconds})
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
