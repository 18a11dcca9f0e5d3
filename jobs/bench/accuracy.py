"""``sray bench accuracy --preset cpu-small|gpu``: zero-shot accuracy with seeds, resumable cell by cell.

1. a procedural world (train scenes + at least 4 unseen test scenes) -> shards, reused when present;
2. **cells**, each a (variant, seed) pretraining followed by a zero-shot evaluation on the unseen
   scenes with 8 source views and whole images (:mod:`sray.jobs.bench.accuracy_cells`): the
   ``long`` cell pretrains the preset's recipe for its whole budget (``synth-cpu-hour`` here), the
   attention ablation (full CRA, cross-only, intra-only, none) pretrains the same recipe for a shorter
   budget with several seeds. A finished cell is stored as one JSON file; a re-run fills only the
   missing cells and resumes an interrupted pretraining from its last checkpoint, so the tables can
   be completed over several runs (``--cells`` and ``--max-minutes`` pick the piece to run);
3. a finetune fleet on the unseen scenes from the ``long`` model: S-Ray finetuning against
   Semantic-NeRF from scratch under the same wall-clock budget, read off at equal budgets;
4. tables (ablation with seed spread, per-class IoU, equal budgets, the targets) and a chart, written
   into docs/benchmarks.md with the exact command, each table with its protocol line(s)
   (:mod:`sray.jobs.bench.accuracy_tables`). The tables are rewritten after every run from whatever
   cells are stored, and say which are still missing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from sray.model.fast_render import FastRender

LONG = "long"
"""Variant name of the cell that pretrains the preset's recipe for its full budget (full CRA)."""

@dataclass(frozen=True)
class Variant:
    """The model settings a row of the benchmark changes."""

    attention: str = "full"
    """``model.attention``."""
    weight_map: str = "radial"
    """``model.weight_map``."""
    inputs: str = "rgb"
    """``model.inputs`` (``rgbd``: the source views' depth guides the samples)."""


VARIANT_SETTINGS = {"full": Variant(), "cross": Variant("cross"), "intra": Variant("intra"), "none": Variant("none"),
                    "full-affine": Variant(weight_map="affine"), "full-rgbd": Variant(inputs="rgbd"),
                    LONG: Variant()}
"""Variant name -> its settings; ``full-affine`` is full CRA with the first (affine) semantic-aware weight
map instead of the default radial one, ``full-rgbd`` full CRA given the source views' depth."""


COMPARED = ("sray", "semantic-nerf")
"""Per-scene methods of the equal-budget table (the paper's per-scene optimisation comparison)."""

EXPERIMENT = "sray-bench-accuracy"
"""Tracking experiment of every pretraining, evaluation and finetune of the benchmark."""


@dataclass(frozen=True)
class World:
    """The procedural scenes of a preset."""

    train_scenes: int
    test_scenes: int
    views: int
    height: int
    width: int
    seed: int = 0


@dataclass(frozen=True)
class Cell:
    """One pretraining + zero-shot evaluation: a variant (``VARIANT_SETTINGS``) and a training seed."""

    variant: str
    seed: int

    @property
    def key(self) -> str:
        """File and job name part: ``full-s0``."""
        return f"{self.variant}-s{self.seed}"

    @classmethod
    def parse(cls, text: str) -> Cell:
        """``full:0`` or ``full-s0`` -> Cell; ValueError names the accepted forms and variants."""
        variant, sep, seed = text.rpartition(":") if ":" in text else text.rpartition("-s")
        if not sep or variant not in VARIANT_SETTINGS or not seed.isdigit():
            raise ValueError(f"cell {text!r}: write VARIANT:SEED (e.g. full:0) with VARIANT one of "
                             f"{', '.join(VARIANT_SETTINGS)}")
        return cls(variant, int(seed))


def seeds(variant: str, n: int) -> tuple[Cell, ...]:
    """Cells of ``variant`` with training seeds 0..n-1."""
    return tuple(Cell(variant, s) for s in range(n))


@dataclass(frozen=True)
class Preset:
    """Sizes and plan of one benchmark preset."""

    world: World
    recipe: str
    """Pretraining recipe every cell starts from (``jobs/recipes.py``)."""
    overrides: tuple[str, ...]
    """``section.field=value`` assignments applied to the recipe in every cell (sizes of small presets)."""
    long_steps: int | None
    """Steps of the ``long`` cell (None = the recipe's own)."""
    ablation_steps: int
    """Steps of every other cell (the shorter ablation budget)."""
    validations: int
    """Held-out validations logged during each pretraining (the cell evaluates its last checkpoint)."""
    ckpt_every: int
    """Checkpoint interval of each pretraining: the most an interrupted cell repeats."""
    plan: tuple[Cell, ...]
    """Cells in the order they run (the long model first: its number is the headline)."""
    eval_sources: int
    """Source views per query in the zero-shot evaluation."""
    eval_fast: FastRender | None
    """Render mode of the zero-shot evaluation (None = the full hierarchical renderer)."""
    budget_s: float
    """Wall-clock budget of each finetune (both methods)."""
    budgets: tuple[float, ...]
    """Equal-budget read-off points (seconds)."""
    fleet_eval_stride: int
    """Finetune curves score every n-th pixel in each direction of the held-out views."""
    fleet_gpus_per_task: float
    """GPUs each finetune task takes (0 on a CPU machine)."""


PRESETS = {
    "cpu-small": Preset(
        world=World(train_scenes=48, test_scenes=4, views=40, height=120, width=160),
        recipe="synth-cpu-hour", overrides=(), long_steps=None, ablation_steps=600, validations=2, ckpt_every=200,
        plan=(Cell(LONG, 0), *seeds("full", 1), *seeds("none", 1), Cell("full", 1), Cell("none", 1),
              Cell("full", 2), Cell("none", 2), Cell("cross", 0), Cell("intra", 0), Cell("full-rgbd", 0)),
        eval_sources=8, eval_fast=FastRender(pixel_stride=1, confidence=0.9),
        budget_s=120.0, budgets=(30.0, 60.0, 120.0), fleet_eval_stride=4,
        fleet_gpus_per_task=0.0),
    "gpu": Preset(
        world=World(train_scenes=96, test_scenes=8, views=100, height=240, width=320),
        recipe="synth-paper", overrides=("data.aug_min_source=2", "data.class_balance=inverse-sqrt",
                                         "data.aug_colour_ev=0.3", "data.aug_channel_ev=0.1",
                                         "data.aug_noise_sigma=3.0"),
        long_steps=20_000, ablation_steps=5_000, validations=4, ckpt_every=1_000,
        plan=(*seeds(LONG, 3), *seeds("full", 3), *seeds("none", 3), Cell("cross", 0), Cell("intra", 0),
              Cell("full-affine", 0), Cell("full-rgbd", 0)),
        eval_sources=8, eval_fast=None, budget_s=600.0, budgets=(60.0, 120.0, 300.0, 600.0), fleet_eval_stride=2,
        fleet_gpus_per_task=0.5),
}
"""Benchmark presets: ``cpu-small`` fits this 2-core machine over a few runs of about an hour;
``gpu`` is the paper-size run for a GPU machine."""


def ensure_world(p: Preset, out: Path) -> Path:
    """The preset's procedural scenes and shards under ``out`` (generated once; kept when complete)."""
    from sray.data_tools.shards.writer import write_shards
    from sray.data_tools.synth.dataset import generate_dataset

    shards = out / "shards"
    if (shards / "manifest.json").exists():
        return shards
    w = p.world
    generate_dataset(out / "scenes", n_train=w.train_scenes, n_test=w.test_scenes, n_views=w.views,
                     height=w.height, width=w.width, seed=w.seed, progress=True)
    write_shards(out / "scenes", shards)
    return shards


def run_accuracy_benchmark(preset: str, out: Path, doc: Path, cells: list[Cell] | None = None,
                           max_minutes: float | None = None, fleet: bool = True,
                           presets: dict[str, Preset] | None = None) -> dict[str, dict]:
    """Run the missing cells (``cells``: a subset of the plan; default all) and, when the long model is
    stored, the fleet; then rewrite the tables in ``doc`` from every stored cell. No new cell starts
    after ``max_minutes``. Returns the stored cells by key."""
    from sray.jobs.bench.accuracy_cells import run_cell, stored_cells
    from sray.jobs.bench.accuracy_tables import write_tables
    from sray.platform.finetune.fleet import unseen_scenes

    p = (presets or PRESETS)[preset]
    out = out.resolve()
    tracking_uri = f"sqlite:///{out / 'mlflow.db'}"
    t0 = time.perf_counter()
    shards = ensure_world(p, out)
    scenes = unseen_scenes(shards)
    wanted = p.plan if cells is None else tuple(c for c in p.plan if c in set(cells))
    for cell in wanted:
        if cell.key in stored_cells(out):
            continue
        if max_minutes is not None and (time.perf_counter() - t0) / 60 >= max_minutes:
            print(f"[bench] {max_minutes:g} min reached: cell {cell.key} and later ones are left for the next run",
                  flush=True)
            break
        run_cell(cell, p, shards, scenes, out, tracking_uri)
    stored = stored_cells(out)
    long_cell = next((c for c in p.plan if c.variant == LONG and c.key in stored), None)
    over = max_minutes is not None and (time.perf_counter() - t0) / 60 >= max_minutes
    if fleet and long_cell is not None and not (out / "fleet" / "done.json").exists() and not over:
        _run_fleet(p, Path(stored[long_cell.key]["checkpoint"]), shards, scenes, out, tracking_uri)
    write_tables(preset, p, stored, out / "fleet", doc)
    return stored


def _run_fleet(p: Preset, checkpoint: Path, shards: Path, scenes: list[str], out: Path, tracking_uri: str) -> None:
    """Finetune every unseen scene with both methods under the same budget; marks the fleet done."""
    import json

    from sray.platform.config.fleet_config import FleetConfig
    from sray.platform.finetune.fleet import run_fleet
    from sray.platform.finetune.methods.registry import METHODS
    from sray.platform.viz.charts import write_fleet_charts

    cfg = FleetConfig()
    cfg.finetune.max_seconds = p.budget_s
    cfg.finetune.max_steps = 100_000
    cfg.finetune.patience = 10_000  # equal budgets: no early stop in the comparison
    cfg.finetune.eval_n_source = p.eval_sources
    cfg.finetune.eval_stride = p.fleet_eval_stride
    cfg.gpus_per_task = p.fleet_gpus_per_task
    cfg.experiment = EXPERIMENT
    results = run_fleet(cfg, checkpoint, shards, scenes, out / "fleet", tracking_uri, list(COMPARED))
    write_fleet_charts(results, out / "fleet" / "charts", METHODS)
    (out / "fleet" / "done.json").write_text(json.dumps({"checkpoint": str(checkpoint)}) + "\n")

