"""Tables, chart and targets of ``sray lab accuracy``, made from its stored cells and fleet results.

Every table is rebuilt from what is stored, so a partial run writes partial tables that name the cells
still missing. Spreads are over training seeds: mean ± sample standard deviation, and the min-max range
used to say whether two variants' spreads overlap.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from sray.lab.accuracy.budgets import BUDGET_TABLE, FORMER_TITLES, budget_means, budget_table, step_zero
from sray.lab.accuracy.cpu_time import budget_points, cpu_time_chart, cpu_time_rows
from sray.lab.accuracy.fleet import fleet_checkpoint
from sray.lab.accuracy.plan import (CPU_BUDGETED, HOUR, HOUR_INTRA, HOUR_WARM, LONG, RECIPE_VARIANT, ROOMS_498,
                                           VARIANT_SETTINGS, Cell, Preset, headline_variant)
from sray.jobs.bench.speed_verdict import checkpoint_label
from sray.lab.accuracy.step_cost import step_cost_chart
from sray.platform.common.bench_doc import Bench, bench_dir, markdown_table, record
from sray.platform.common.eval_protocol import caption_lines
from sray.platform.finetune.methods.sray_method import NAME as SRAY
from sray.platform.viz.curves import read_fleet_results
from sray.platform.viz.seed_chart import write_seed_chart

ZERO_SHOT_TARGET = 0.50
"""Target: zero-shot mIoU of the long (recipe) model, RGB-only."""
FINETUNE_RATIO_TARGET = 0.60
"""Target: zero-shot mIoU as a fraction of S-Ray's score after a 60 s finetune."""
ABLATION_MARGIN = 0.05
"""Target: full CRA at least this much mIoU above no attention, with non-overlapping seed ranges."""
FINETUNE_READ_S = 60.0
"""Finetune budget (seconds) the zero-shot ratio is read at."""


def accuracy_bench(preset: str) -> Bench:
    """The benchmark's section (and folder of data and charts) for one preset."""
    return Bench(f"accuracy-{preset}", f"Accuracy, {preset}")


def variant_label(variant: str, p: Preset) -> str:
    """Row label: the variant's name; for the cells at the recipe's CPU budget the recipe's name with the room count
    of their world (``synth-cpu-hour, 498 rooms``) and the variant's name where its settings differ from the recipe's
    (``hour-none: synth-cpu-hour, 498 rooms``); for the ``long`` cell the first form of the recipe it kept
    (``full, first synth-cpu-hour``)."""
    if variant in CPU_BUDGETED:
        settings = VARIANT_SETTINGS[variant]
        label = f"{p.recipe}, {settings.train_scenes or p.world.train_scenes} rooms"
        recipe = replace(VARIANT_SETTINGS[RECIPE_VARIANT], train_scenes=None)
        return label if replace(settings, train_scenes=None) == recipe else f"{variant}: {label}"
    return {LONG: f"full, first {p.recipe}"}.get(variant, variant)


def by_variant(p: Preset, stored: dict[str, dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """Stored cells of each planned variant, in plan order, seeds ascending (variants with none left out)."""
    rows: dict[str, list[dict[str, Any]]] = {}
    for cell in p.plan:
        if cell.key in stored:
            rows.setdefault(cell.variant, []).append(stored[cell.key])
    return {v: sorted(cells, key=lambda c: c["seed"]) for v, cells in rows.items()}


def mean_spread(values: list[float]) -> tuple[float, float | None]:
    """Mean and sample standard deviation (None for a single value)."""
    return float(np.mean(values)), (float(np.std(values, ddof=1)) if len(values) > 1 else None)


def _pct(value: float | None, digits: int = 2) -> str:
    return "—" if value is None or not np.isfinite(value) else f"{100 * value:.{digits}f}"


def _stored_mean(cells: list[dict[str, Any]], key: str, show: Any) -> str:
    """``show`` of the mean of ``key`` over the cells holding it, with ``(k/n)`` when only k of n cells do (cells
    stored before the field existed); ``—`` when none does."""
    values = [c[key] for c in cells if c.get(key) is not None]
    if not values:
        return "—"
    return show(float(np.mean(values))) + ("" if len(values) == len(cells) else f" ({len(values)}/{len(cells)})")


def seed_table(p: Preset, stored: dict[str, dict[str, Any]],
               step_times: dict[str, Any] | None = None) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the zero-shot table: one row per variant, its seeds' mean ± spread (and its
    seconds per pretraining step where ``step_times``, as ``accuracy_step_cost`` stores them, holds it)."""
    timed = (step_times or {}).get("variants", {})
    header = ["variant", "steps", "seeds", "mIoU %", "mIoU % per seed", "held-out train-scene mIoU %", "total acc %",
              "class-avg acc %", "PSNR dB", "pretrain min", "pretrain CPU min", "eval min",
              *(["s / step (side by side)"] if timed else [])]
    rows = []
    for variant, cells in by_variant(p, stored).items():
        mean, spread = mean_spread([c["miou"] for c in cells])
        planned = sum(1 for c in p.plan if c.variant == variant)
        rows.append([variant_label(variant, p), ", ".join(sorted({str(c["steps"]) for c in cells})),
                     f"{len(cells)}/{planned}", _pct(mean) + ("" if spread is None else f" ± {_pct(spread)}"),
                     " / ".join(_pct(c["miou"]) for c in cells), _stored_mean(cells, "heldout_miou", _pct),
                     _pct(np.mean([c["total_acc"] for c in cells])),
                     _pct(np.mean([c["class_avg_acc"] for c in cells])), f"{np.mean([c['psnr'] for c in cells]):.2f}",
                     f"{np.mean([c['train_s'] for c in cells]) / 60:.1f}",
                     _stored_mean(cells, "train_cpu_s", lambda v: f"{v / 60:.1f}"),
                     f"{np.mean([c['eval_s'] for c in cells]) / 60:.1f}",
                     *([f"{timed[variant]['s_per_step']:.3f}" if variant in timed else "—"] if timed else [])])
    return header, rows


def class_table(p: Preset, stored: dict[str, dict[str, Any]]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the per-class IoU table: one row per class, one column per variant (mean
    over its seeds of the class's IoU; ``—`` where no test scene holds the class)."""
    groups = by_variant(p, stored)
    if not groups:
        return [], []
    names = next(iter(groups.values()))[0]["class_names"]
    header = ["class", *(f"{variant_label(v, p)} IoU %" for v in groups)]
    rows = []
    for k, name in enumerate(names):
        cells = []
        for variant_cells in groups.values():
            values = [c["class_iou"][k] for c in variant_cells if c["class_iou"][k] is not None]
            cells.append(_pct(float(np.mean(values))) if values else "—")
        rows.append([name, *cells])
    return header, rows


def shown_headline(p: Preset, stored: dict[str, dict[str, Any]]) -> str:
    """The variant the targets read: the headline model's (the recipe as it is) when a cell of it is stored, else
    the recipe's earlier forms (``hour-intra`` at its 5,000-step cap, ``hour-warm2d`` with full CRA, ``hour-498``
    before its 2D warm-up, ``hour`` on the preset world, then ``long``), else the headline's (not run yet)."""
    groups = by_variant(p, stored)
    earlier = (headline_variant(p), HOUR_INTRA, HOUR_WARM, ROOMS_498, HOUR, LONG)
    return next((v for v in earlier if groups.get(v)), headline_variant(p))


def fleet_from_headline(p: Preset, stored: dict[str, dict[str, Any]], fleet_dir: Path) -> bool:
    """Whether the finished fleet in ``fleet_dir`` finetuned from a stored cell of the headline the targets read
    (:func:`shown_headline`): only then is its S-Ray score the denominator of the zero-shot ratio."""
    checkpoints = {c["checkpoint"] for c in by_variant(p, stored).get(shown_headline(p, stored), [])}
    return fleet_checkpoint(fleet_dir) in checkpoints


def targets(p: Preset, stored: dict[str, dict[str, Any]], sray_at_60: float | None) -> list[str]:
    """One line per target of the benchmark: the measured value and whether it is met (or what is missing);
    ``sray_at_60``: S-Ray's fleet score at the read-off budget, finetuned from the shown headline model."""
    groups = by_variant(p, stored)
    lines = []
    headline = shown_headline(p, stored)
    headline_cells = groups.get(headline, [])
    if headline_cells:
        zero_shot = float(np.mean([c["miou"] for c in headline_cells]))
        n = len(headline_cells)
        lines.append(f"- Zero-shot mIoU of the {variant_label(headline, p)} model ({n} seed{'s' * (n > 1)}): "
                     f"{_pct(zero_shot)}% against the {_pct(ZERO_SHOT_TARGET, 0)}% target: "
                     f"{'met' if zero_shot >= ZERO_SHOT_TARGET else 'not met'}.")
        if sray_at_60 is not None:
            ratio = zero_shot / sray_at_60 if sray_at_60 > 0 else float("nan")
            lines.append(f"- Zero-shot / S-Ray after a {FINETUNE_READ_S:.0f} s finetune: {_pct(zero_shot)} / "
                         f"{_pct(sray_at_60)} = {ratio:.2f} against {FINETUNE_RATIO_TARGET:.2f}: "
                         f"{'met' if ratio >= FINETUNE_RATIO_TARGET else 'not met'}.")
    else:
        lines.append(f"- Zero-shot mIoU of the {p.recipe} model: cell {Cell(headline_variant(p), 0).key} not run yet.")
    full, none = groups.get("full", []), groups.get("none", [])
    if len(full) > 1 and len(none) > 1:
        f, n = [c["miou"] for c in full], [c["miou"] for c in none]
        gap = float(np.mean(f) - np.mean(n))
        apart = min(f) > max(n) or min(n) > max(f)
        met = gap >= ABLATION_MARGIN and min(f) > max(n)
        lines.append(f"- Full CRA − none: {100 * gap:+.2f} points (target ≥ +{100 * ABLATION_MARGIN:.0f}); seed "
                     f"ranges {_pct(min(f))}–{_pct(max(f))} and {_pct(min(n))}–{_pct(max(n))} "
                     f"{'do not overlap' if apart else 'overlap'}: {'met' if met else 'not met'}.")
    else:
        lines.append("- Full CRA − none: needs at least 2 seeds of each.")
    rgbd = groups.get("full-rgbd", [])
    if rgbd and full:
        same_seed = {c["seed"]: c["miou"] for c in full}
        paired = [(c["miou"], same_seed[c["seed"]]) for c in rgbd if c["seed"] in same_seed]
        if paired:
            gain = float(np.mean([d - r for d, r in paired]))
            lines.append(f"- What depth buys (RGB-D vs RGB, full CRA, same seeds {sorted(c['seed'] for c in rgbd)}): "
                         f"{100 * gain:+.2f} points of zero-shot mIoU (measured; no target).")
    return lines


def _step_cost_link(preset: str, p: Preset, groups: dict[str, list[dict[str, Any]]], step_times: dict[str, Any],
                    caption: str, figures: Path, doc: Path) -> str:
    """The mIoU-against-step-time chart of the stored variants, and its note and link for the doc."""
    timed = step_times["variants"]
    chart = step_cost_chart({variant_label(v, p): [100 * c["miou"] for c in cells] for v, cells in groups.items()},
                            {variant_label(v, p): timed[v]["s_per_step"] for v in groups if v in timed},
                            {variant_label(v, p): cells[0]["steps"] for v, cells in groups.items()},
                            figures / "zero_shot_vs_step_time.png",
                            f"Zero-shot mIoU against training step time ({preset})", caption)
    return (f"Step times (`--step-times`): one pretraining step of each variant (its cells' recipe and model "
            f"section, {next(iter(timed.values()))['rays']} rays per batch, {p.world.width}x{p.world.height}, its "
            "precision, "
            "synthetic scene), fresh processes alternating round by round, median of the rounds; "
            f"{step_times['machine']}.\n\n![zero-shot mIoU against step time]({os.path.relpath(chart, doc.parent)})")


def _table(header: list[str], rows: list[list[str]], captions: list[str]) -> str:
    """A Markdown table with its protocol caption lines under it."""
    return "\n".join([markdown_table(header, rows), "", *captions])


def _fleet_source(fleet_dir: Path) -> str:
    """What the fleet in ``fleet_dir`` finetuned from, for its table's caption."""
    source = fleet_checkpoint(fleet_dir)
    return "the headline model" if source is None else f"checkpoint `{checkpoint_label(Path(source))}`"


def write_tables(preset: str, p: Preset, stored: dict[str, dict[str, Any]], fleet_dir: Path, doc: Path,
                 step_times: dict[str, Any] | None = None, errors: dict[str, str] | None = None) -> None:
    """Write the benchmark's tables into its section of ``doc`` (replacing earlier ones of this preset and
    device) and its chart(s) beside their data (``doc.bench_dir``); ``step_times`` (as
    ``accuracy_step_cost`` stores them) adds the step-time column and the mIoU-against-step-time chart;
    ``errors`` (cell key -> error of its last launch) names the missing cells that failed."""
    bench = accuracy_bench(preset)
    figures = bench_dir(doc, bench)
    figures.mkdir(parents=True, exist_ok=True)
    captions = caption_lines((variant_label(c["variant"], p), c["protocol"])
                             for c in sorted(stored.values(), key=lambda c: c["cell"]))
    missing = [c.key for c in p.plan if c.key not in stored]
    failed = [key for key in errors or {} if key in missing]
    links = []
    if stored:
        groups = by_variant(p, stored)
        chart = write_seed_chart({variant_label(v, p): [100 * c["miou"] for c in cells] for v, cells in groups.items()},
                                 "zero-shot mIoU %", f"Zero-shot mIoU on unseen procedural scenes ({preset})",
                                 " ".join(captions), figures / "zero_shot_seeds.png")
        links.append(f"![zero-shot mIoU over seeds]({os.path.relpath(chart, doc.parent)})")
        if step_times:
            links.append(_step_cost_link(preset, p, groups, step_times, " ".join(captions), figures, doc))
    points, untimed = budget_points(p, stored)

    results = read_fleet_results(fleet_dir) if fleet_dir.is_dir() else []
    from_headline = fleet_from_headline(p, stored, fleet_dir)
    sray_at_60 = budget_means(results, (FINETUNE_READ_S,)).get(SRAY, [None])[0] if from_headline else None
    w = p.world
    notes = [f"World: {w.train_scenes} train + {w.test_scenes} unseen test procedural scenes, {w.views} views of "
             f"{w.width}x{w.height}, world seed {w.seed}. Each cell pretrains the `{p.recipe}` recipe "
             f"(the ablation rows for {p.ablation_steps} steps) with its training seed and is scored on the "
             "unseen scenes from its last checkpoint; scores per scene, then averaged over scenes; mean ± "
             "sample standard deviation over seeds. Pretrain/eval minutes: wall time on this machine "
             "(a resumed pretraining counts every run that trained it and ended).",
             "Missing cells: " + (", ".join(missing) if missing else "none") + ".",
             *([f"Failed in their last run (the error is in the cell's trial record, `study/trials/<cell>/"
                f"trial.json`; a re-run runs them again): {', '.join(failed)}."] if failed else []),
             "Targets:", *targets(p, stored, sray_at_60),
             *([f"- Zero-shot / S-Ray after a {FINETUNE_READ_S:.0f} s finetune: not read: the stored fleet "
                f"finetuned from {_fleet_source(fleet_dir)}, not from the headline model (a fleet run from it "
                "measures the ratio)."] if results and not from_headline else []), "", *links]
    header, rows = seed_table(p, stored, step_times)
    record(bench, "Zero-shot with seeds", _table(header, rows, captions), doc, "\n".join(notes))
    if points:
        chart = cpu_time_chart(points, figures / "miou_vs_cpu_hours.png",
                               f"Zero-shot and held-out training-scene mIoU against pretraining CPU hours ({preset})",
                               " ".join(captions))
        header, rows = cpu_time_rows(points)
        record(bench, "Accuracy against pretraining CPU time", _table(header, rows, captions), doc,
               "An arm is a set of model and data settings; its cells differ in budget (the ablation steps, "
               f"`{LONG}`, or the recipe's own CPU-second budget, `{HOUR}`) and seed. CPU hours: the job's CPU "
               "seconds summed over its ranks and their loader processes (`train/cpu_seconds`), mean over seeds; "
               "the chart's band is the seeds' range."
               + (f" Not charted (stored before CPU time was recorded): {', '.join(untimed)}." if untimed else "")
               + f"\n\n![mIoU against pretraining CPU hours]({os.path.relpath(chart, doc.parent)})")
    header, rows = class_table(p, stored)
    if rows:
        record(bench, "Per-class IoU, zero-shot", _table(header, rows, captions), doc,
               "Each class's IoU from one confusion matrix per scene, averaged over the test scenes that hold "
               "the class, then over seeds.")
    if results:
        fleet_links = []
        for chart in sorted((fleet_dir / "charts").glob("*.png")):
            shutil.copy(chart, figures / chart.name)
            fleet_links.append(f"![{chart.stem}]({os.path.relpath(figures / chart.name, doc.parent)})")
        header, rows = budget_table(results, (0.0, *p.budgets), _pct)
        record(bench, BUDGET_TABLE,
               _table(header, rows, caption_lines((r["method"], r.get("protocol")) for r in results)),
               doc, f"Finetunes from {_fleet_source(fleet_dir)}, {p.budget_s:.0f} s wall-clock budget each, equal "
                    "for every method, read off at the last held-out evaluation before each budget (0 s = "
                    f"{step_zero(results)}). Columns: every registered method with stored results, with the inputs "
                    "its results' protocol records; a method whose requirement a run did not meet (2d-transfer "
                    "without `--segmenter`) was left out of that run's fleet.\n\n" + "\n".join(fleet_links),
               replaces=FORMER_TITLES)
