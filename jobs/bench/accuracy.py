"""``sray bench accuracy --preset cpu-small|gpu``: the paper's ablation and per-scene comparison, measured.

1. procedural scenes -> shards;
2. pretraining on the train scenes once per attention variant (full CRA, cross-only, intra-only,
   none) and once for full CRA with the first (affine) semantic-aware weight map, zero-shot
   evaluation of each on the unseen test scenes (the paper's ablation table);
3. a finetune fleet on the unseen scenes from the full model, S-Ray finetune against Semantic-NeRF
   from scratch under the same wall-clock budget, read off at equal budgets (the paper's
   per-scene optimisation table);
4. tables and charts appended to docs/benchmarks.md with the exact command, each table with the
   protocol line(s) of the numbers in it (:func:`sray.platform.common.eval_protocol.caption_lines`); the
   stored results (``<out>/eval/<variant>/metrics.json``, the fleet's ``result.json`` files) carry
   the protocol descriptor.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

VARIANTS = ("full", "cross", "intra", "none", "full-affine")
"""Rows of the ablation: the attention variants in the paper's expected order (best first), then the
full model with the first (``affine``) semantic-aware weight map, against the default ``radial`` one."""

COMPARED = ("sray", "semantic-nerf")
"""Per-scene methods of the equal-budget table (the paper's per-scene optimisation comparison), by
registry name; columns are headed with their chart labels."""

VARIANT_SETTINGS = {"full": ("full", "radial"), "cross": ("cross", "radial"), "intra": ("intra", "radial"),
                    "none": ("none", "radial"), "full-affine": ("full", "affine")}
"""Row name -> (``model.attention``, ``model.weight_map``)."""


@dataclass(frozen=True)
class Preset:
    """Sizes of one benchmark preset."""

    train_scenes: int
    test_scenes: int
    views: int
    height: int
    width: int
    steps: int
    rays: int
    n_coarse: int
    n_fine: int
    n_source: int
    workers: int
    gpus_per_worker: float
    precision: str
    budget_s: float
    """Wall-clock budget of each finetune (both methods)."""
    budgets: tuple[float, ...]
    """Equal-budget read-off points (seconds)."""
    validations: int
    """Held-out validations during each pretraining (the best one's checkpoint is used)."""
    fleet_eval_stride: int
    """Finetune curves score every n-th pixel in each direction of the held-out views."""


PRESETS = {
    "cpu-small": Preset(train_scenes=4, test_scenes=2, views=40, height=120, width=160, steps=300, rays=256,
                        n_coarse=24, n_fine=24, n_source=4, workers=2, gpus_per_worker=0.0, precision="no",
                        budget_s=150.0, budgets=(30.0, 60.0, 150.0), validations=1,
                        fleet_eval_stride=4),
    "gpu": Preset(train_scenes=12, test_scenes=4, views=100, height=240, width=320, steps=20_000, rays=1024,
                  n_coarse=64, n_fine=64, n_source=8, workers=1, gpus_per_worker=1.0, precision="bf16",
                  budget_s=600.0, budgets=(60.0, 120.0, 300.0, 600.0), validations=4,
                  fleet_eval_stride=2),
}


def _pretrain(variant: str, p: Preset, shards: Path, out: Path, tracking_uri: str) -> Path:
    """Train one ablation row (``VARIANT_SETTINGS``); returns its best checkpoint (by held-out validation mIoU)."""
    from sray.jobs.recipes import get_recipe
    from sray.platform.train.launcher import launch_training

    cfg = get_recipe("synth-small" if p.gpus_per_worker == 0 else "synth-paper")
    (cfg.model.attention, cfg.model.weight_map), cfg.model.n_source = VARIANT_SETTINGS[variant], p.n_source
    cfg.model.n_coarse, cfg.model.n_fine = p.n_coarse, p.n_fine
    cfg.data.shards, cfg.data.rays_per_batch, cfg.data.top_k = str(shards), p.rays, max(p.n_source + 2, 6)
    cfg.optim.steps = p.steps
    cfg.run.workers, cfg.run.gpus_per_worker, cfg.run.precision = p.workers, p.gpus_per_worker, p.precision
    cfg.run.output_dir, cfg.run.tracking_uri = str(out / "train"), tracking_uri
    cfg.run.experiment, cfg.run.register_model = "sray-bench-accuracy", ""
    cfg.run.val_every = cfg.run.ckpt_every = max(p.steps // p.validations, 1)
    cfg.run.name = f"bench-{variant}-{time.strftime('%Y%m%d-%H%M%S', time.gmtime())}"
    outcome = launch_training(cfg)
    return outcome.best_checkpoint or outcome.latest_checkpoint


def _at_budget(result: dict[str, Any], budget: float, key: str) -> float:
    """The held-out score a finetune had reached after ``budget`` seconds (last evaluation before it)."""
    from sray.platform.viz.curves import step_hold

    curve = [c for c in result.get("curve", []) if c.get(key) is not None]
    x = np.array([c["wall_s"] for c in curve], dtype=float)
    y = np.array([c[key] for c in curve], dtype=float)
    return float(step_hold(x, y, np.array([budget]))[0])


def _table(header: list[str], rows: list[list[str]], captions: list[str]) -> str:
    """A Markdown table with its protocol caption lines under it."""
    lines = [" | ".join(header), " | ".join("---" for _ in header)]
    return "\n".join(lines + [" | ".join(r) for r in rows] + ["", *captions])


def run_accuracy_benchmark(preset: str, out: Path, doc: Path) -> None:
    """Run every stage and append the tables (and chart links) to ``doc``."""
    from sray.data_tools.shards.writer import write_shards
    from sray.data_tools.synth.dataset import generate_dataset
    from sray.jobs.bench.doc import record
    from sray.platform.common.eval_protocol import caption_lines
    from sray.platform.config.fleet_config import FleetConfig
    from sray.platform.eval.zero_shot import evaluate_checkpoint
    from sray.platform.finetune.fleet import run_fleet, unseen_scenes
    from sray.platform.finetune.methods.registry import METHODS, get_method
    from sray.platform.viz.charts import write_fleet_charts

    p = PRESETS[preset]
    out = out.resolve()
    tracking_uri = f"sqlite:///{out / 'mlflow.db'}"
    t0 = time.perf_counter()
    generate_dataset(out / "scenes", n_train=p.train_scenes, n_test=p.test_scenes, n_views=p.views,
                     height=p.height, width=p.width, seed=0, progress=True)
    shards = out / "shards"
    write_shards(out / "scenes", shards)
    scenes = unseen_scenes(shards)

    rows, checkpoints, protocols = [], {}, []
    for variant in VARIANTS:
        start = time.perf_counter()
        checkpoints[variant] = _pretrain(variant, p, shards, out, tracking_uri)
        train_s = time.perf_counter() - start
        report = evaluate_checkpoint(checkpoints[variant], shards, scenes, out / "eval" / variant,
                                     n_source=p.n_source, stride=1, tracking_uri=tracking_uri,
                                     experiment="sray-bench-accuracy", progress=False)
        mean, ssim = report["mean"], report["mean"]["colour"]["ssim"]
        protocols.append((variant, report["protocol"]))
        rows.append([variant, f"{100 * mean['dataset_level']['miou']:.2f}",
                     f"{100 * mean['dataset_level']['total_acc']:.2f}",
                     f"{100 * mean['dataset_level']['class_avg_acc']:.2f}",
                     f"{100 * mean['per_image']['miou']:.2f}", f"{mean['colour']['psnr_db']:.2f}",
                     "—" if ssim is None else f"{ssim:.3f}", f"{train_s / 60:.1f}"])
    ablation = _table(["variant", "mIoU %", "total acc %", "class-avg acc %", "per-image mIoU %", "PSNR dB",
                       "SSIM", "pretrain min"], rows, caption_lines(protocols))

    fleet_cfg = FleetConfig()
    fleet_cfg.finetune.max_seconds = p.budget_s
    fleet_cfg.finetune.max_steps = 100_000
    fleet_cfg.finetune.patience = 10_000  # equal budgets: no early stop in the comparison
    fleet_cfg.finetune.eval_n_source = p.n_source
    fleet_cfg.finetune.eval_stride = p.fleet_eval_stride
    fleet_cfg.gpus_per_task = 0.5 if p.gpus_per_worker else 0.0
    fleet_cfg.experiment = "sray-bench-accuracy"
    results = run_fleet(fleet_cfg, checkpoints["full"], shards, scenes, out / "fleet", tracking_uri, list(COMPARED))
    charts = write_fleet_charts(results, out / "fleet" / "charts", METHODS)
    budget_rows = []
    for budget in (0.0, *p.budgets):
        cells = [f"{budget:.0f}"]
        for method in COMPARED:
            values = [_at_budget(r, budget, "miou") for r in results if r["method"] == method and r["status"] == "finished"]
            values = [v for v in values if np.isfinite(v)]
            cells.append(f"{100 * np.mean(values):.2f}" if values else "-")
        budget_rows.append(cells)
    equal_budget = _table(["budget s", *(f"{get_method(m).style.label} mIoU %" for m in COMPARED)], budget_rows,
                          caption_lines((r["method"], r.get("protocol")) for r in results))

    figures = doc.parent / "benchmarks" / f"accuracy-{preset}"
    figures.mkdir(parents=True, exist_ok=True)
    links = []
    for chart in charts:
        shutil.copy(chart, figures / chart.name)
        links.append(f"![{chart.stem}](benchmarks/accuracy-{preset}/{chart.name})")
    notes = (f"Scores per scene, then averaged over the {len(scenes)} unseen scenes. "
             f"Pretraining: {p.steps} steps, {p.rays} rays, "
             f"{p.n_coarse}+{p.n_fine} samples, {p.workers} worker(s), on {p.train_scenes} procedural scenes "
             f"({p.width}x{p.height}, {p.views} views). Finetunes: {p.budget_s:.0f} s wall-clock budget each, "
             f"equal for both methods, read off at the last held-out evaluation before each budget (0 s = "
             f"zero-shot for S-Ray, untrained for Semantic-NeRF). Total benchmark wall time "
             f"{(time.perf_counter() - t0) / 60:.1f} min.\n\n" + "\n".join(links))
    record(f"Accuracy: attention ablation, zero-shot ({preset})", ablation, doc)
    record(f"Accuracy: S-Ray finetune vs Semantic-NeRF at equal wall-clock budgets ({preset})",
           equal_budget, doc, notes)
