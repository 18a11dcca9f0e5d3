"""One trial of a study (an arm at a seed), the point function the study engine runs: make the arm's world, train
the base recipe with the arm's overrides for the budget (resuming an interrupted job), score its last checkpoint on
the study's evaluations and store the result file (``sray.lab.studies.results``).

The trial evaluates the job's **last** checkpoint, never one picked on the rooms it reports: the test rooms
(``zero_shot``: the world's unseen rooms, or with ``splits`` the in-distribution split's own world, beside the
appearance- and geometry-shifted ones, ``zero_shot_appearance`` and ``zero_shot_geometry``), held-out views of the
first training rooms (``held_out``) and the validation rooms (``validation``: rooms no result is reported on, where
arms are chosen). With ``calibration`` the fast rule's temperature is first fitted on the validation rooms and every
split is scored at it (the protocol names it). With ``fleet`` the checkpoint is also finetuned per test room, with
``ceilings`` its ceiling rows are scored (:mod:`sray.lab.studies.fleet_ceilings`). A rerun reuses the calibration
and the splits a stopped trial already scored (:mod:`sray.lab.studies.resume`).
"""

from __future__ import annotations

import shutil
import subprocess
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from sray.data_tools.synth.world import World, make_world
from sray.lab.studies.results import FORMAT, write_result
from sray.lab.studies.fleet_ceilings import ceilings_metrics, fleet_metrics
from sray.lab.studies.resume import stored_calibration, stored_report
from sray.lab.studies.spec import ROOM_SPLITS, Arm, StudySpec, assignments, load_study
from sray.model.fast_render import FastRender
from sray.platform.checkpoints.folders import CheckpointManager, load_checkpoint, read_meta
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.common.machine import describe_machine
from sray.platform.config.recipes import get_recipe
from sray.platform.config.train_config import CONFIG_FILE, TrainConfig, apply_override, load_job_config
from sray.platform.eval.eval_model import checkpoint_model
from sray.platform.eval.zero_shot import (METRICS_FILE, calibrate, evaluate_checkpoint, select_scenes, training_scenes,
                                          write_json_atomic)
from sray.platform.sweep.study import TrialContext
from sray.platform.train.launcher import budget_spent, launch_training

EXPERIMENT = "sray-studies"
"""Tracking experiment of every study's training jobs and evaluations."""


def world_folder(studies: Path, world: World) -> Path:
    """Where a world's scenes and shards live: ``<studies work folder>/worlds/<its settings>``, one folder per distinct
    world, shared by every study that trains or scores on it (``synth-cpu-hour``'s default shards are the one of
    ``jobs/studies/hour-recipe.yaml``); a test split other than in-distribution and a randomisation add a suffix."""
    return Path(studies) / "worlds" / (f"train{world.train_scenes}-test{world.test_scenes}-v{world.views}-"
                                       f"{world.height}x{world.width}-s{world.seed}"
                                       + ("" if world.split == "in-distribution" else f"-{world.split}")
                                       + (f"-r{world.randomise:g}" if world.randomise else ""))


def trial_config(spec: StudySpec, arm: Arm, seed: int, shards: Path, out: Path, tracking_uri: str) -> TrainConfig:
    """The base recipe with the study's and the arm's overrides, the arm's budget, the seed and the study's folders."""
    cfg = get_recipe(spec.recipe)
    for assignment in assignments(spec.sets) + arm.overrides():
        apply_override(cfg, assignment)
    budget = arm.budget or spec.budget
    cfg.optim.cpu_seconds = budget.cpu_seconds or 0.0
    if budget.steps:
        cfg.optim.steps = budget.steps
    cfg.data.shards, cfg.run.seed = str(shards), seed
    cfg.run.output_dir, cfg.run.tracking_uri = str(Path(out) / "train"), tracking_uri
    cfg.run.experiment, cfg.run.register_model = EXPERIMENT, ""
    cfg.run.ckpt_every = min(cfg.run.ckpt_every, cfg.optim.steps)
    cfg.run.val_every = min(cfg.run.val_every, cfg.run.ckpt_every)
    cfg.run.name = f"{spec.name}-{arm.name}-s{seed}"
    return cfg


def train(cfg: TrainConfig) -> Path:
    """Train ``cfg`` to the end of its budget, resuming its unfinished job; its last checkpoint. RuntimeError when the
    job ends before its budget."""
    job_dir = Path(cfg.run.output_dir) / cfg.run.name
    latest = CheckpointManager(job_dir / "checkpoints").latest() if job_dir.exists() else None
    if latest is not None and budget_spent(job_dir, cfg):
        return latest
    if (job_dir / CONFIG_FILE).is_file() and latest is not None:
        saved = load_job_config(cfg.run.output_dir, cfg.run.name)
        saved.run.tracking_uri = cfg.run.tracking_uri
        outcome = launch_training(saved, resume=True)
    else:
        shutil.rmtree(job_dir, ignore_errors=True)  # stopped before its first checkpoint: start over
        outcome = launch_training(cfg)
    if outcome.latest_checkpoint is None or not budget_spent(job_dir, cfg):
        raise RuntimeError(f"{job_dir}: training ended {outcome.status} before its budget; run the study again to "
                           "resume it")
    return outcome.latest_checkpoint


def split_metrics(report: dict[str, Any], shards: Path, scenes: list[str]) -> dict[str, Any]:
    """An evaluation report as a result's metrics block (percent; per-class IoU averaged over the rooms holding the
    class, by class name)."""
    mean = report["mean"]["dataset_level"]
    _, meta = select_scenes(shards, scenes)
    names = list(meta[scenes[0]]["class_names"])
    per_class: dict[str, float] = {}
    for i, name in enumerate(names):
        values = [s["dataset_level"]["iou_per_class"][i] for s in report["scenes"].values()]
        values = [v for v in values if v is not None]
        if values:
            per_class[name] = round(100 * sum(values) / len(values), 2)
    pct = {k: None if mean.get(k) is None else round(100 * mean[k], 2) for k in ("miou", "total_acc", "class_avg_acc")}
    return {**pct, "per_class_iou": per_class, "rooms": len(scenes), "views": report["mean"].get("n_views"),
            "protocol": EvalProtocol.from_json(report["protocol"]).describe()}


def _rounded(seconds: float | None) -> float | None:
    """Seconds to a tenth (None stays None)."""
    return None if seconds is None else round(float(seconds), 1)


def current_commit(repo: Path) -> str | None:
    """The short hash of the checkout ``repo`` (None outside a git checkout)."""
    done = subprocess.run(["git", "-C", str(repo), "rev-parse", "--short=7", "HEAD"], capture_output=True, text=True)
    return done.stdout.strip() or None if done.returncode == 0 else None


def evaluation_rooms(spec: StudySpec, shards: Path, studies: Path) -> dict[str, tuple[Path, list[str]]]:
    """Split -> (shard folder, scene names) of every evaluation of ``spec`` (``zero_shot`` always, first); each split
    with a world of its own is generated under ``<studies>/worlds/`` on first use, the others read ``shards``."""
    rooms = {}
    for split in dict.fromkeys(["zero_shot", *(e for e in spec.evaluations if e in ROOM_SPLITS)]):
        world = spec.evaluation_world(split)
        folder = shards if world is None else make_world(world, world_folder(studies, world), progress=False)
        rooms[split] = (folder, training_scenes(folder, spec.held_out_rooms) if split == "held_out" else
                        select_scenes(folder, None)[0])
    return rooms


def run_trial(spec: StudySpec, arm_name: str, seed: int, out: Path, tracking_uri: str) -> dict[str, Any]:
    """Train and score (``arm_name``, ``seed``) of ``spec`` in the study's work folder ``out`` (its worlds one level up,
    shared by the studies); store and return its result."""
    arm = spec.arms[arm_name]
    shards = make_world(spec.arm_world(arm), world_folder(Path(out).parent, spec.arm_world(arm)), progress=False)
    cfg = trial_config(spec, arm, seed, shards, out, tracking_uri)
    checkpoint = train(cfg)
    rooms = evaluation_rooms(spec, shards, Path(out).parent)
    fast = None if spec.eval_fast is None else FastRender(pixel_stride=spec.eval_fast[0], confidence=spec.eval_fast[1])
    if spec.calibration_stride is not None:
        fitted_at = Path(out) / "eval" / "calibration" / f"{cfg.run.name}.json"
        fitted = stored_calibration(fitted_at, checkpoint, rooms["validation"][0], spec.eval_sources,
                                    spec.calibration_stride)
        if fitted is None:
            fitted = calibrate(checkpoint_model(checkpoint, fast=fast), rooms["validation"][0], spec.eval_sources,
                               spec.calibration_stride)
            write_json_atomic({**fitted, "checkpoint": str(checkpoint)}, fitted_at)
        fast = replace(fast, temperature=fitted["temperature"])
    metrics = {}
    for split, (folder, scenes) in rooms.items():
        out_dir = Path(out) / "eval" / split / cfg.run.name
        report = stored_report(out_dir / METRICS_FILE, checkpoint, folder, scenes, spec.eval_sources, fast)
        if report is None:
            report = evaluate_checkpoint(checkpoint, folder, scenes, out_dir, n_source=spec.eval_sources,
                                         tracking_uri=tracking_uri, experiment=EXPERIMENT, progress=False, fast=fast)
        metrics[split] = split_metrics(report, folder, scenes)
    if spec.fleet is not None:
        metrics["fleet"] = fleet_metrics(spec.fleet, checkpoint, *rooms["zero_shot"], Path(out) / "eval" / "fleet" /
                                         cfg.run.name, tracking_uri, EXPERIMENT, spec.eval_sources)
    if spec.ceilings is not None:
        metrics["ceilings"] = ceilings_metrics(spec.ceilings, checkpoint, shards, spec.held_out_rooms,
                                               spec.eval_sources, fast, Path(out) / "eval" / "ceilings" / cfg.run.name)
    counters = load_checkpoint(checkpoint).get("counters", {})
    steps = int(read_meta(checkpoint)["step"])
    budget = arm.budget or spec.budget
    result = {"format": FORMAT, "study": spec.name, "arm": arm_name, "seed": seed, "recipe": spec.recipe,
              "overrides": {**spec.sets, **arm.sets},
              "budget": {"cpu_seconds": budget.cpu_seconds, "steps": budget.steps},
              "trained": {"ray_steps": max(steps - cfg.optim.warmup_2d_steps, 0),
                          "cpu_seconds": _rounded(counters.get("cpu_seconds")),
                          "wall_seconds": _rounded(counters.get("wall_seconds")),
                          "peak_memory_gib": None if counters.get("peak_memory_mb") is None else
                          round(counters["peak_memory_mb"] / 1024, 3)},
              "metrics": metrics, "machine": describe_machine(), "commit": current_commit(spec.path.parent),
              "source": "run"}
    write_result(spec.results_dir, result)
    return result


def study_trial(point: dict[str, Any], ctx: TrialContext, spec_path: str, out: str, tracking_uri: str) -> dict:
    """The point function of a study: run the trial ``point`` names (``arm``, ``seed``) and report its scores."""
    started = time.perf_counter()
    result = run_trial(load_study(Path(spec_path)), point["arm"], int(point["seed"]), Path(out), tracking_uri)
    ctx.report({split: float(block["miou"]) for split, block in result["metrics"].items()
                if block.get("miou") is not None} | {"trial_s": time.perf_counter() - started})
    return result
