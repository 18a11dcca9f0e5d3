"""The cells of ``sray lab accuracy``, each a trial of the study engine: pretrain a (variant, seed), evaluate it
zero-shot, return the cell's record.

The cells are a study under ``<out>/study`` (``sray.platform.sweep.incremental``): the record a cell returns is
kept in its trial's record (``study/trials/<key>/trial.json``) and the cell counts as done once it is there; a
later run never trains or evaluates it again. A cell that raises is recorded with its error and the next
cells run; a later run runs it again. Cells stored by the benchmark's earlier harness
(``<out>/cells/<key>.json``) are imported as finished trials, never recomputed.

A cell's training job is named ``bench-<variant>-s<seed>`` under ``<out>/train``; a job left unfinished
by an earlier run resumes from its latest checkpoint, a finished one is not trained again. The cell
evaluates the job's **last** checkpoint (the end of its budget; no checkpoint is picked on the test
scenes). The cells run one at a time, one after another in one trial process (Tune's ``reuse_actors``) that
only drives them: each cell's pretraining runs in its own Ray Train workers, which reserve the CPUs and GPUs;
its evaluation runs in the trial process once they have ended, with as many torch threads as they had CPUs.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import time
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from sray.data_tools.shards.manifest import read_manifest
from sray.lab.accuracy.plan import CPU_BUDGETED, EXPERIMENT, LONG, VARIANT_SETTINGS, Cell, Preset
from sray.lab.accuracy.worlds import cell_shards
from sray.platform.checkpoints.folders import CheckpointManager, load_checkpoint, read_meta
from sray.platform.config.recipes import get_recipe
from sray.platform.config.train_config import apply_override, load_job_config
from sray.platform.eval.zero_shot import evaluate_checkpoint, training_scenes
from sray.platform.sweep.capacity import TRIAL_RESOURCES
from sray.platform.sweep.incremental import import_result, missing, run_missing, stored_results
from sray.platform.sweep.outcomes import TrialOutcome
from sray.platform.sweep.study import StudySettings, TrialContext
from sray.platform.sweep.trial_files import ERRORED, TRIALS, read_record
from sray.platform.train.launcher import budget_spent, init_ray, launch_training

if TYPE_CHECKING:
    from sray.platform.config.train_config import TrainConfig

STUDY_DIR = "study"
"""Sub-folder of the benchmark's work folder holding the cells' study (one trial per cell key)."""
OLD_CELLS_DIR = "cells"
"""Sub-folder where the benchmark's earlier harness stored one JSON file per finished cell (imported)."""
HELD_OUT_SCENES = 8
"""Training scenes whose held-out views each cell also scores (fitting, beside the zero-shot transfer)."""
TRAIN_SECONDS_FILE = "bench_train_seconds.json"
"""File in a cell's job folder summing the wall seconds of every run that trained it (resumes included)."""


def _train_seconds(job_dir: Path, add: float = 0.0) -> float:
    """The job's training wall seconds so far, after adding ``add`` (stored in :data:`TRAIN_SECONDS_FILE`)."""
    path = job_dir / TRAIN_SECONDS_FILE
    total = (json.loads(path.read_text())["seconds"] if path.exists() else 0.0) + add
    if add:
        path.write_text(json.dumps({"seconds": total}) + "\n")
    return total


def stored_cells(out: Path) -> dict[str, dict[str, Any]]:
    """Every finished cell's record under ``out`` (imported ones included), by key."""
    return stored_results(Path(out) / STUDY_DIR)


def cell_errors(out: Path) -> dict[str, str]:
    """Key -> error of every cell whose last launch raised (the next run that asks for it runs it again)."""
    root = Path(out) / STUDY_DIR / TRIALS
    records = {p.name: read_record(p) for p in sorted(root.iterdir()) if p.is_dir()} if root.is_dir() else {}
    return {key: r.error for key, r in records.items() if r.outcome == ERRORED}


def import_old_cells(out: Path) -> list[str]:
    """Import every ``<out>/cells/<key>.json`` of the earlier harness as the finished trial ``key`` (unless the
    study has finished that cell already); the keys imported."""
    folder = Path(out) / OLD_CELLS_DIR
    files = sorted(folder.glob("*.json")) if folder.is_dir() else []
    return [p.stem for p in files if import_result(Path(out) / STUDY_DIR, p.stem, json.loads(p.read_text()), p)]


def cell_config(cell: Cell, p: Preset, shards: Path, out: Path, tracking_uri: str) -> TrainConfig:
    """The training config of ``cell``: the preset's recipe and overrides, the variant's model settings
    (attention, the weight net's map, inputs and tau, the source inputs, fine samples, heads, source-view loss,
    2D warm-up, scene interleaving, step cap and CPU budget, then its overrides), the cell's seed and budget, and the
    benchmark's folders."""
    cfg = get_recipe(p.recipe)
    for assignment in p.overrides:
        apply_override(cfg, assignment)
    variant = VARIANT_SETTINGS[cell.variant]
    cfg.model.attention, cfg.model.weight_map, cfg.model.inputs = variant.attention, variant.weight_map, variant.inputs
    cfg.model.fine_samples, cfg.model.weight_inputs = variant.fine_samples, variant.weight_inputs
    if variant.n_heads is not None:
        cfg.model.n_heads = variant.n_heads
    if variant.tau is not None:
        cfg.model.tau = variant.tau
    cfg.model.lambda_src_sem, cfg.optim.warmup_2d_steps = variant.lambda_src_sem, variant.warmup_2d_steps
    cfg.model.lambda_depth = variant.lambda_depth
    cfg.data.visit_samples, cfg.data.cache_scenes = variant.visit_samples, variant.cache_scenes
    if variant.step_cap is not None:
        cfg.optim.steps = variant.step_cap
    if variant.cpu_seconds is not None:
        cfg.optim.cpu_seconds = variant.cpu_seconds
    for assignment in variant.overrides:
        apply_override(cfg, assignment)
    if cell.variant not in CPU_BUDGETED:  # step-budgeted cells: the ablation budget, or the long one
        cfg.optim.cpu_seconds = 0.0
        cfg.optim.steps = p.ablation_steps if cell.variant != LONG else (p.long_steps or cfg.optim.steps)
        cfg.run.val_every = max(cfg.optim.steps // p.validations, 1)
    cfg.data.shards = str(shards)
    cfg.run.seed = cell.seed
    cfg.run.output_dir, cfg.run.tracking_uri = str(out / "train"), tracking_uri
    cfg.run.experiment, cfg.run.register_model = EXPERIMENT, ""
    cfg.run.ckpt_every = min(p.ckpt_every, cfg.optim.steps)
    cfg.run.name = f"bench-{cell.key}"
    return cfg


def pretrain(cell: Cell, p: Preset, shards: Path, out: Path, tracking_uri: str) -> tuple[Path, float, bool]:
    """Train ``cell`` to the end of its budget, resuming an unfinished job of the same name from its latest
    checkpoint (a job folder without one is started over).

    Returns (its last checkpoint, wall seconds of every run that trained it, whether an earlier run had
    started it).
    RuntimeError when the job stops before its last step.
    """
    cfg = cell_config(cell, p, shards, out, tracking_uri)
    job_dir = Path(cfg.run.output_dir) / cfg.run.name
    latest = CheckpointManager(job_dir / "checkpoints").latest() if job_dir.exists() else None
    if latest is not None and budget_spent(job_dir, cfg):
        return latest, _train_seconds(job_dir), True
    start = time.perf_counter()
    if latest is None and job_dir.exists():
        shutil.rmtree(job_dir)  # stopped before its first checkpoint: nothing to resume, start over
    resumed = latest is not None
    if resumed:
        saved = load_job_config(cfg.run.output_dir, cfg.run.name)
        saved.run.tracking_uri = tracking_uri
        outcome = launch_training(saved, resume=True)
    else:
        outcome = launch_training(cfg)
    total_s = _train_seconds(job_dir, time.perf_counter() - start)
    last = outcome.latest_checkpoint
    if last is None or not budget_spent(job_dir, cfg):
        raise RuntimeError(f"{job_dir}: pretraining of cell {cell.key} ended {outcome.status} before step "
                           f"{cfg.optim.steps} and its CPU budget; re-run `sray lab accuracy` to resume it")
    return last, total_s, resumed


def class_iou(report: dict[str, Any]) -> list[float | None]:
    """Per-class IoU of an evaluation report: each class's IoU averaged over the scenes whose ground truth
    holds it (None for a class absent from every scene)."""
    rows = np.array([[np.nan if v is None else v for v in s["dataset_level"]["iou_per_class"]]
                     for s in report["scenes"].values()], dtype=float)
    present = ~np.isnan(rows)
    sums = np.where(present, rows, 0.0).sum(axis=0)
    counts = present.sum(axis=0)
    return [float(s / c) if c else None for s, c in zip(sums, counts, strict=True)]


def run_cell(cell: Cell, p: Preset, base: Path, scenes: list[str], out: Path, tracking_uri: str) -> dict[str, Any]:
    """Pretrain and evaluate ``cell`` on its world (the preset world's shards ``base``, or its variant's own
    room count with the same test scenes); return its record (what ``stored_cells`` gives once its trial ends)."""
    shards, world_cpu_s = cell_shards(cell.variant, p, base, out)
    print(f"[bench] cell {cell.key}: pretraining on {shards}", flush=True)
    checkpoint, train_s, resumed = pretrain(cell, p, shards, out, tracking_uri)
    run = cell_config(cell, p, shards, out, tracking_uri).run
    torch.set_num_threads(max(1, int(run.workers * run.cpus_per_worker)))  # the CPUs its workers held
    print(f"[bench] cell {cell.key}: zero-shot evaluation of {checkpoint}", flush=True)
    start = time.perf_counter()
    report = evaluate_checkpoint(checkpoint, shards, scenes, out / "eval" / cell.key, n_source=p.eval_sources,
                                 stride=1, tracking_uri=tracking_uri, experiment=EXPERIMENT, progress=True,
                                 fast=p.eval_fast)
    mean = report["mean"]
    manifest = read_manifest(shards)
    first = manifest.scenes[scenes[0]].meta
    # fitting against transfer: every held-out view of the first HELD_OUT_SCENES training scenes, with the
    # zero-shot protocol (the same sources rule, render and whole images)
    seen = training_scenes(shards, HELD_OUT_SCENES)
    held_out = evaluate_checkpoint(checkpoint, shards, seen, out / "eval-heldout" / cell.key, n_source=p.eval_sources,
                                   stride=1, tracking_uri=tracking_uri, experiment=EXPERIMENT, progress=True,
                                   fast=p.eval_fast)
    state = load_checkpoint(checkpoint)
    record = {
        "cell": cell.key, "variant": cell.variant, "seed": cell.seed,
        **dataclasses.asdict(VARIANT_SETTINGS[cell.variant]),
        "shards": str(shards), "world_cpu_s": world_cpu_s,
        "recipe": p.recipe, "steps": int(read_meta(checkpoint)["step"]), "checkpoint": str(checkpoint),
        "train_s": train_s, "resumed": resumed, "eval_s": time.perf_counter() - start,
        "miou": mean["dataset_level"]["miou"], "total_acc": mean["dataset_level"]["total_acc"],
        "class_avg_acc": mean["dataset_level"]["class_avg_acc"], "miou_per_image": mean["per_image"]["miou"],
        "psnr": mean["colour"]["psnr_db"], "ssim": mean["colour"]["ssim"],
        "scene_miou": {name: report["scenes"][name]["dataset_level"]["miou"] for name in scenes},
        "heldout_miou": held_out["mean"]["dataset_level"]["miou"], "heldout_scenes": seen,
        "heldout_class_iou": class_iou(held_out),
        "train_cpu_s": state.get("counters", {}).get("cpu_seconds"),
        "class_iou": class_iou(report), "class_names": list(first["class_names"]),
        "protocol": report["protocol"], "metrics_path": report["metrics_path"],
    }
    print(f"[bench] cell {cell.key}: zero-shot mIoU {100 * record['miou']:.2f}%, held-out views of "
          f"{len(seen)} training scenes {100 * record['heldout_miou']:.2f}%", flush=True)
    return record


def cell_trial(point: dict[str, Any], ctx: TrialContext, preset: Preset, shards: str, scenes: list[str], out: str,
               tracking_uri: str) -> dict[str, Any]:
    """The point function of the cells' study: run the cell ``point`` names (``variant``, ``seed``)."""
    record = run_cell(Cell(point["variant"], int(point["seed"])), preset, Path(shards), scenes, Path(out),
                      tracking_uri)
    ctx.report({"miou": float(record["miou"]), "heldout_miou": float(record["heldout_miou"])})
    return record


def run_cells(cells: tuple[Cell, ...], p: Preset, shards: Path, scenes: list[str], out: Path, tracking_uri: str,
              start_by: float = 0.0) -> list[TrialOutcome]:
    """Run the cells without a stored record, in plan order, one at a time; none starts after ``start_by``
    (Unix time, 0 = no limit). Returns every cell's outcome."""
    plan = {c.key: {"variant": c.variant, "seed": c.seed} for c in cells}
    settings = StudySettings(folder=Path(out) / STUDY_DIR, metric="miou", mode="max", max_concurrent=1,
                             trial_resources=TRIAL_RESOURCES, start_by=start_by, reuse_actors=True, label="bench")
    if missing(settings.folder, plan):
        init_ray(None)
    point_fn = partial(cell_trial, preset=p, shards=str(shards), scenes=list(scenes), out=str(out),
                       tracking_uri=tracking_uri)
    return run_missing(plan, point_fn, settings)
