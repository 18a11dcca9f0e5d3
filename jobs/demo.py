"""``sray demo``, the README's main job, under ``--out``: scenes -> checked shards -> a loader sample's picture -> a
short S-Ray training on local Ray -> 2d-transfer's segmenter for the same CPU seconds -> zero-shot evaluation -> a
fly-through -> a finetune fleet -> charts, the results table and the ``sray ui`` command."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from sray.data_tools.atomic import save_png
from sray.data_tools.loader.sample_types import TrainSample
from sray.data_tools.loader.shard_loader import make_train_loader
from sray.data_tools.shards.manifest import read_manifest, unseen_scenes
from sray.data_tools.shards.writer import DatasetRejected
from sray.data_tools.synth.world import SCENES, World, WorldFolderError, make_world
from sray.jobs.bench.segmenter import run_segmenter
from sray.jobs.bench.speed_accuracy import Setting, measure
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
from sray.platform.viz.palette import palette

RECIPE = "synth-demo"
"""The recipe S-Ray trains with; the 2D segmenter takes its data settings and feature width."""
FLEET_METHODS = ["sray", "semantic-nerf", "2d-transfer"]
"""The fleet's methods (it adds ``sray-rgbd`` beside the RGB-D 2d-transfer)."""


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
    """Run every stage of ``sray demo``, printing where each result went; exit 1 if the data fails its checks."""
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
    cfg.optim.steps, cfg.run.seed = args.steps, args.seed
    cfg.run.output_dir, cfg.run.ckpt_every = str(args.out / "train"), max(args.steps // 2, 1)
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
    fleet_cfg.finetune.max_seconds, fleet_cfg.transfer.segmenter = args.finetune_seconds, str(segmenter_dir)
    fleet_cfg.finetune.held_out.n_source, fleet_cfg.finetune.held_out.stride = cfg.model.n_source, 2 * args.eval_stride
    scenes_fleet = scenes_test[:args.fleet_scenes] if args.fleet_scenes > 0 else scenes_test
    _say(f"8/9 finetune fleet on {len(scenes_fleet)} of the {len(scenes_test)} unseen scenes "
         f"({', '.join(scenes_fleet)}): S-Ray (RGB, from the trained model), Semantic-NeRF (RGB, from scratch), S-Ray "
         "given the source depth (RGB-D, the same model) and 2d-transfer (RGB-D, from the segmenter of stage 6: "
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
    """Stage 6: train 2d-transfer's segmenter on the train scenes' source pools into ``out`` for ``sray_cpu_s`` (what
    S-Ray's training spent) or ``cap`` when smaller and not 0; its record and a note of the budget and why."""
    budget = sray_cpu_s if cap == 0 else min(sray_cpu_s, cap)
    note = (f"{budget:.0f} CPU s, capped by --segmenter-cpu-seconds below the {sray_cpu_s:.0f} CPU s S-Ray's training "
            "spent" if budget < sray_cpu_s else f"{budget:.0f} CPU s, what S-Ray's training spent (equal CPU)")
    _say(f"6/9 training the 2D segmenter of 2d-transfer (ResUNet encoder + linear head; 2d-transfer carries its labels "
         f"into a new view by the source views' depth: an RGB-D method) on the train scenes' train split (held-out "
         f"views left out) for {note}")
    return run_segmenter(shards, budget, out, RECIPE, seed), note


def _flythrough(checkpoint: Path, shards: Path, scene: str, out: Path, n_frames: int) -> Path:
    """The WebM of ``sray render``'s default zero-shot fly-through, ``n_frames`` long, tracked in the default store."""
    plan = plan_flythrough(shards, scene, path="spline", n_frames=n_frames)
    net, about = render_model(checkpoint, None, scene)
    fly = Flythrough(net, plan, 8, FastRender())
    result = tracked_flythrough(fly, out, torch.device("cpu"), about=about, label="zero-shot", tracker="mlflow",
                                tracking_uri="", experiment="sray-render")
    return Path(result["files"]["webm"])


def _speed_line(checkpoint: Path, shards: Path, n_source: int) -> str:
    """One line of ``sray bench speed-accuracy``: full against fast render on each unseen scene's first test view."""
    full, fast = measure(checkpoint, shards, [Setting("full", n_source), Setting("fast", n_source, fast=FastRender())],
                         1, progress=False)
    return (f"[demo] speed vs accuracy (first test view per unseen scene, whole image): full render "
            f"{full['s_per_view']:.1f} s/view, mIoU {full['miou']:.1f}%; fast render {fast['s_per_view']:.2f} s/view "
            f"({full['s_per_view'] / fast['s_per_view']:.0f}x), mIoU {fast['miou']:.1f}% "
            f"({fast['miou'] - full['miou']:+.1f} points); more settings: sray bench speed-accuracy")


def write_sample_picture(sample: TrainSample, class_names: list[str], path: Path, ignore_id: int = 255) -> Path:
    """The sampled rays' colours and labels over the query frame (a sample lacks its image), beside the m sources."""
    src = sample.sources.rgb.permute(0, 2, 3, 1).numpy()  # (m, H, W, 3)
    m, h, w = src.shape[:3]
    uv = sample.pixels.numpy()  # (R, 2)
    labels = sample.target_label.numpy()  # (R,)
    colours = sample.target_rgb.numpy()  # (R, 3)
    pal = palette(len(class_names)) / 255.0
    label_colours = np.where((labels == ignore_id)[:, None], 0.0, pal[np.minimum(labels, len(class_names) - 1)])

    cols = max(m, 2)
    fig = Figure(figsize=(3 * cols, 5.2))
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, cols, squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, colour, title in ((axes[0, 0], colours, "query: sampled ray colours"),
                              (axes[0, 1], label_colours, "query: sampled ray labels")):
        ax.axis("on")
        ax.set(facecolor="0.85", xticks=[], yticks=[], xlim=(-0.5, w - 0.5), ylim=(h - 0.5, -0.5))
        ax.scatter(uv[:, 0], uv[:, 1], c=colour, s=6)
        ax.set_title(title, fontsize=9)
    present = sorted(int(c) for c in np.unique(labels) if c != ignore_id)
    handles = [Line2D([], [], marker="s", ls="", color=pal[c], label=class_names[c]) for c in present]
    if (labels == ignore_id).any():
        handles.append(Line2D([], [], marker="s", ls="", color="black", label=f"ignore ({ignore_id})"))
    axes[0, 2 if cols > 2 else 1].legend(handles=handles, loc="center", fontsize=7, frameon=False, ncol=2)
    for i in range(m):
        axes[1, i].imshow(src[i])
        axes[1, i].set_title(f"source {i + 1}", fontsize=9)
    fig.suptitle(f"scene {sample.scene}, query view {sample.query_id}: {len(uv)} rays, "
                 f"{m} source views, depth range {sample.near:.2f}-{sample.far:.2f} m", fontsize=10)
    fig.tight_layout()
    save_png(fig, path, 100)
    return path
