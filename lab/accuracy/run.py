"""``sray lab accuracy --preset cpu-small|gpu``: zero-shot accuracy with seeds, resumable cell by cell.

1. a procedural world (train scenes + at least 4 unseen test scenes) -> shards, reused when present;
2. **cells**, each a (variant, seed) pretraining followed by a zero-shot evaluation on the unseen
   scenes with 8 source views and whole images, each a trial of the study engine
   (:mod:`sray.lab.accuracy.cells`): the ``long`` cell pretrains the preset's recipe for its whole
   budget (``synth-cpu-hour`` here), the attention ablation (full CRA, cross-only, intra-only, none)
   pretrains the same recipe for a shorter budget with several seeds. A finished cell's record is kept in
   its trial's record; a re-run runs only the cells without one (a failed cell again) and resumes an
   interrupted pretraining from its last checkpoint, so the tables can be completed over several runs
   (``--cells`` and ``--max-minutes`` pick the piece to run; no cell starts after the limit);
3. a finetune fleet on the unseen scenes from the headline model (``headline_variant``: the recipe at its own CPU
   budget, ``hour-intra``, in ``cpu-small``; ``long`` in ``gpu``), its first stored seed: every registered method whose
   requirements are met (:mod:`sray.lab.accuracy.fleet`: S-Ray finetuning, Semantic-NeRF from scratch,
   and ``2d-transfer`` when a segmenter is given) under the same wall-clock budget, read off at equal budgets;
4. tables (ablation with seed spread, per-class IoU, equal budgets, the targets) and a chart, written
   into docs/benchmarks.md with the exact command, each table with its protocol line(s)
   (:mod:`sray.lab.accuracy.tables`). The tables are rewritten after every run from whatever
   cells are stored, and say which are still missing;
5. with ``step_times``, the training cost: one pretraining step of every stored variant timed side by side
   in fresh processes (:mod:`sray.lab.accuracy.step_cost`), stored beside the cells, and the chart
   of zero-shot mIoU against seconds per step.
"""

from __future__ import annotations

import time
from pathlib import Path

from sray.data_tools.shards.manifest import unseen_scenes
from sray.jobs.bench.probes import resolve_device
from sray.lab.accuracy.cells import cell_errors, import_old_cells, run_cells, stored_cells
from sray.lab.accuracy.fleet import compared_methods, fleet_config, run_comparison
from sray.lab.accuracy.plan import PRESETS, Cell, Preset, headline_variant
from sray.lab.accuracy.step_cost import measure_step_times, read_step_times, store_step_times
from sray.lab.accuracy.tables import by_variant, write_tables
from sray.lab.accuracy.worlds import make_bench_world
from sray.platform.common.bench_doc import machine_line


def run_accuracy_benchmark(preset: str, out: Path, doc: Path, cells: list[Cell] | None = None,
                           max_minutes: float | None = None, fleet: bool = True,
                           presets: dict[str, Preset] | None = None, step_times: bool = False,
                           segmenter: Path | None = None) -> dict[str, dict]:
    """Run the missing cells (``cells``: a subset of the plan; default all; a cell that raises is recorded
    and the next ones run) and, when the headline model is stored, the fleet of every registered method whose
    requirements are met (``segmenter``: the 2D segmenter ``2d-transfer`` starts from; checked before any cell
    runs); with ``step_times``, time a pretraining step of every stored variant side by side; then rewrite the
    tables in ``doc`` from every stored cell, fleet result and the stored step times. No new cell starts after
    ``max_minutes``. Returns the stored cells by key."""
    p = (presets or PRESETS)[preset]
    out = out.resolve()
    tracking_uri = f"sqlite:///{out / 'mlflow.db'}"
    start_by = 0.0 if max_minutes is None else time.time() + 60 * max_minutes
    cfg, methods, left_out = compared_methods(fleet_config(p, segmenter))
    if fleet:
        for name, why in left_out.items():
            print(f"[bench] fleet: method {name} left out: {why}", flush=True)
    shards = make_bench_world(p.world, out, progress=True)
    scenes = unseen_scenes(shards)
    imported = import_old_cells(out)
    if imported:
        print(f"[bench] cells {', '.join(imported)} read from {out / 'cells'} (not computed again)", flush=True)
    wanted = p.plan if cells is None else tuple(c for c in p.plan if c in set(cells))
    outcomes = run_cells(wanted, p, shards, scenes, out, tracking_uri, start_by)
    over = bool(start_by) and time.time() >= start_by
    left = [o.key for o in outcomes if o.reason == "unfinished"]
    if over and left:
        print(f"[bench] {max_minutes:g} min reached: cells {', '.join(left)} are left for the next run", flush=True)
    stored = stored_cells(out)
    headline = headline_variant(p)
    fleet_cell = next((c for c in p.plan if c.variant == headline and c.key in stored), None)
    if fleet and fleet_cell is not None and not over:
        run_comparison(cfg, methods, Path(stored[fleet_cell.key]["checkpoint"]), shards, scenes, out / "fleet",
                       tracking_uri)
    if step_times and stored:
        _time_steps(p, stored, out)
    write_tables(preset, p, stored, out / "fleet", doc, read_step_times(out), cell_errors(out))
    return stored


def _time_steps(p: Preset, stored: dict[str, dict], out: Path) -> None:
    """Time one pretraining step of every variant with a stored cell, side by side, and store the result."""
    machine = machine_line()  # before the timing: the load it reports is the one the steps start under
    times = measure_step_times(p, list(by_variant(p, stored)), resolve_device("auto"))
    store_step_times(out, times, machine)
