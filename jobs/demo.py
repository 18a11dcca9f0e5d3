"""The README's main job, run by ``sray demo`` on the embedded defaults.

procedural scenes -> ``sray data check`` -> shards (+ verification) -> a picture of a loader
sample -> a short S-Ray training run on local Ray with two CPU workers, tracked in MLflow -> the 2D
segmenter of ``2d-transfer`` trained on the same train scenes for the CPU seconds that training spent (capped
by ``--segmenter-cpu-seconds``) -> zero-shot evaluation on the unseen scenes -> a short fly-through video of
one of them -> a finetune fleet (S-Ray, Semantic-NeRF, and the RGB-D pair: S-Ray given the source depth beside
2d-transfer) on them -> accuracy-against-time charts -> the results table and the ``sray ui`` command. Each
printed table ends with its protocol line (sources, stride, render mode, inputs), and the fleet's table names each
row's inputs.
Everything goes under ``--out`` (default ``outputs/demo``); the MLflow store is the working
directory's default SQLite store.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

from sray.data_tools.loader.shard_loader import make_train_loader
from sray.data_tools.shards.manifest import read_manifest, unseen_scenes
from sray.data_tools.shards.writer import DatasetRejected
from sray.data_tools.synth.world import SCENES, World, WorldFolderError, make_world
from sray.jobs.bench.segmenter import run_segmenter
from sray.jobs.bench.speed_accuracy import Setting, measure
from sray.jobs.sample_picture import write_sample_picture
from sray.model.fast_render import FastRender
from sray.platform.checkpoints.folders import load_checkpoint
from sray.platform.config.fleet_config import FleetConfig
from sray.platform.config.recipes import get_recipe
from sray.platform.eval.segmenter import SegmenterRecord
from sray.platform.eval.zero_shot import evaluate_checkpoint, format_table
from sray.platform.finetune.fleet import run_fleet
from sray.platform.finetune.fleet_report import results_table
from sray.platform.finetune.render_model import render_model
from sray.platform.render.flythrough import Flythrough
from sray.platform.render.plan import plan_flythrough
from sray.platform.render.tracked import tracked_flythrough
from sray.platform.train.launcher import launch_training


RECIPE = "synth-demo"
"""The recipe S-Ray trains with; the 2D segmenter takes its data settings (sources per step, neighbours,
augmentation, class balance) and feature width."""
FLEET_METHODS = ["sray", "semantic-nerf", "2d-transfer"]
"""The per-scene methods the demo asks its fleet for; the fleet adds ``sray-rgbd`` beside the RGB-D 2d-transfer
(``registry.with_depth_twins``)."""


def _say(msg: str) -> None:
    print(f"[demo] {msg}", flush=True)


def _sray_command() -> str:
    """How to call ``sray`` again from here: the script this process was started as, else ``sray``."""
    script = Path(sys.argv[0])
    if script.name == "sray" and script.exists():
        try:
            return str(script.resolve().relative_to(Path.cwd()))
        except ValueError:
            return str(script)
    return "sray"


def run_demo(args: argparse.Namespace) -> int:
    """Run every stage of ``sray demo`` (``args``: its parsed flags), printing where each result went; exit 1 if
    the data fails its checks."""
    t0 = time.perf_counter()
    world = World(train_scenes=args.train_scenes, test_scenes=args.test_scenes, views=args.views,
                  height=args.height, width=args.width, seed=args.seed)
    _say(f"1/9 generating {args.train_scenes} train + {args.test_scenes} unseen test scenes "
         f"({args.views} views, {args.width}x{args.height}) in {args.out / SCENES}, unless already there")
    try:
        shards = make_world(world, args.out)
    except (DatasetRejected, WorldFolderError) as err:
        print(err, file=sys.stderr)
        return 1
    _say("2/9 the scenes passed sray data check before sharding")
    _say(f"3/9 sharded into {shards}")
    manifest = read_manifest(shards)
    _say(f"    {len(manifest.scenes)} scenes, {len(manifest.shards)} shards, checksums verified")
    n_source = 4
    sample = next(iter(make_train_loader(shards, n_source=n_source, top_k=6, rays_per_batch=512,
                                         batches_per_epoch=1, rank=0, world_size=1, num_workers=0, seed=args.seed)))
    class_names = next(iter(manifest.scenes.values())).meta["class_names"]
    picture = write_sample_picture(sample, class_names, args.out / "loader_sample.png")
    _say(f"4/9 a training sample from the loader: {picture}")
    if args.steps <= 0:
        _say(f"done in {time.perf_counter() - t0:.0f} s (data only); results under {args.out.resolve()}")
        return 0
    cfg = get_recipe(RECIPE)
    cfg.data.shards = str(shards)
    # --steps keeps the recipe's share of 2D-only warm-up steps and its data order (a loader epoch per checkpoint)
    cfg.optim.warmup_2d_steps = round(args.steps * cfg.optim.warmup_2d_steps / cfg.optim.steps)
    cfg.optim.steps = args.steps
    cfg.run.output_dir = str(args.out / "train")
    cfg.run.seed = args.seed
    cfg.run.ckpt_every = max(args.steps // 2, 1)
    cfg.run.val_every = args.steps  # one validation, at the end: it costs about a minute on 2 cores
    _say(f"5/9 training S-Ray ({RECIPE}) for {args.steps} steps on local Ray with {cfg.run.workers} CPU workers, the "
         f"first {cfg.optim.warmup_2d_steps} on the source views' labels alone")
    outcome = launch_training(cfg)
    checkpoint = outcome.best_checkpoint or outcome.latest_checkpoint
    sray_cpu_s = float(load_checkpoint(outcome.latest_checkpoint)["counters"]["cpu_seconds"])
    segmenter_dir = args.out / "segmenter"
    segmenter, budget_note = train_segmenter_stage(shards, segmenter_dir, args.segmenter_cpu_seconds, sray_cpu_s,
                                                   args.seed)
    scenes_test = unseen_scenes(shards)
    _say(f"7/9 zero-shot evaluation of {checkpoint.name} on the unseen scenes {', '.join(scenes_test)} "
         f"(scored on 1 pixel in every {args.eval_stride}x{args.eval_stride} block)")
    report = evaluate_checkpoint(checkpoint, shards, scenes_test, args.out / "eval", n_source=cfg.model.n_source,
                                 stride=args.eval_stride, progress=True)
    print(format_table(report), flush=True)
    print(_speed_line(checkpoint, shards, cfg.model.n_source), flush=True)
    clip = _flythrough(checkpoint, shards, scenes_test[0], args.out / "render", args.clip_frames)
    _say(f"    a {args.clip_frames}-frame fly-through of {scenes_test[0]} (RGB, labels, depth, confidence): {clip}")
    _say(f"    render any scene yourself:  {_sray_command()} render --checkpoint {checkpoint} --data {shards} "
         f"--scene {scenes_test[0]} --out {args.out / 'render'}")
    fleet_cfg = FleetConfig()
    fleet_cfg.finetune.max_seconds = args.finetune_seconds
    fleet_cfg.finetune.held_out.n_source = cfg.model.n_source
    fleet_cfg.finetune.held_out.stride = 2 * args.eval_stride
    fleet_cfg.transfer.segmenter = str(segmenter_dir)
    scenes_fleet = scenes_test[:args.fleet_scenes] if args.fleet_scenes > 0 else scenes_test
    _say(f"8/9 finetune fleet on {len(scenes_fleet)} of the {len(scenes_test)} unseen scenes "
         f"({', '.join(scenes_fleet)}): S-Ray (RGB, from the trained model), "
         f"Semantic-NeRF (RGB, from scratch), S-Ray given the source depth (RGB-D, the same model) and 2d-transfer "
         f"(RGB-D, from the segmenter of stage 6: "
         f"{segmenter.training['cpu_seconds_budget']:.0f} CPU s of pretraining against S-Ray's {sray_cpu_s:.0f}), "
         f"{args.finetune_seconds:.0f} s budget each, early stopping on held-out mIoU")
    results = run_fleet(fleet_cfg, checkpoint, shards, scenes_fleet, args.out / "fleet", "", FLEET_METHODS)
    _say(f"9/9 results (charts in {args.out / 'fleet' / 'charts'}):")
    print(results_table(results), flush=True)
    _say(f"pretraining before the fleet: S-Ray {args.steps} steps, {sray_cpu_s:.0f} CPU s; 2d-transfer's "
         f"{segmenter.budget()} (budget {budget_note})")
    _say(f"done in {(time.perf_counter() - t0) / 60:.1f} min; results under {args.out.resolve()}")
    _say(f"browse everything in the MLflow dashboard:  {_sray_command()} ui   (then open the printed URL)")
    return 0


def train_segmenter_stage(shards: Path, out: Path, cap: float, sray_cpu_s: float,
                          seed: int) -> tuple[SegmenterRecord, str]:
    """Stage 6: train 2d-transfer's 2D segmenter on the train scenes of ``shards`` (their source pools: the ``train``
    split minus held-out views) with :data:`RECIPE`'s data settings into folder ``out``, for ``sray_cpu_s`` (the CPU
    seconds S-Ray's training spent) or ``cap`` when that is smaller and not 0. Returns its record and a note of the
    budget it got and why."""
    budget = sray_cpu_s if cap == 0 else min(sray_cpu_s, cap)
    note = (f"{budget:.0f} CPU s, capped by --segmenter-cpu-seconds below the {sray_cpu_s:.0f} CPU s S-Ray's training "
            "spent" if budget < sray_cpu_s else f"{budget:.0f} CPU s, what S-Ray's training spent (equal CPU)")
    _say(f"6/9 training the 2D segmenter of 2d-transfer (ResUNet encoder + linear head; 2d-transfer carries its labels "
         f"into a new view by the source views' depth: an RGB-D method) on the train scenes' train split (held-out "
         f"views left out) for {note}")
    return run_segmenter(shards, budget, out, RECIPE, seed), note


def _flythrough(checkpoint: Path, shards: Path, scene: str, out: Path, n_frames: int) -> Path:
    """Render the zero-shot fly-through ``sray render`` makes by default (spline through the scene's cameras, fast
    mode, 8 sources), ``n_frames`` long, tracked in the working directory's store; returns the WebM's path."""
    plan = plan_flythrough(shards, scene, path="spline", n_frames=n_frames)
    net, about = render_model(checkpoint, None, scene)
    fly = Flythrough(net, plan, 8, FastRender())
    result = tracked_flythrough(fly, out, torch.device("cpu"), about=about, label="zero-shot", tracker="mlflow",
                                tracking_uri="", experiment="sray-render")
    return Path(result["files"]["webm"])


def _speed_line(checkpoint: Path, shards: Path, n_source: int) -> str:
    """One line of ``sray bench speed-accuracy``: the full render against the fast render mode on the first
    test view of each unseen scene (paired, whole images, ``n_source`` source views)."""
    full, fast = measure(checkpoint, shards, [Setting("full", n_source), Setting("fast", n_source, fast=FastRender())],
                         1, progress=False)
    return (f"[demo] speed vs accuracy (first test view per unseen scene, whole image): full render "
            f"{full['s_per_view']:.1f} s/view, mIoU {full['miou']:.1f}%; fast render {fast['s_per_view']:.2f} s/view "
            f"({full['s_per_view'] / fast['s_per_view']:.0f}x), mIoU {fast['miou']:.1f}% "
            f"({fast['miou'] - full['miou']:+.1f} points); more settings: sray bench speed-accuracy")
