"""Stage ``ray``: ``sray train`` on procedural shards (one worker, rank 0 killed half-way by the fault hook, resumed),
``sray eval`` and ``sray render`` of its checkpoint; 2 workers on one GPU refused before Ray starts (NCCL would)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from unittest import mock

from sray.data_tools.shards.manifest import unseen_scenes
from sray.data_tools.synth.world import make_world
from sray.platform.common.fault_hook import ENV_VAR, KILL_MARKER
from sray.platform.config.recipes import get_recipe
from sray.platform.train.inputs import InputError

from .context import FULL_STACK, CheckContext, skipped_without
from .report import StageResult
from .synthetic import toy_world

RECIPE = "synth-gpu-minutes"
RENDER_SIZE, RENDER_FRAMES = "320x240", 60
"""Fly-through size (width x height) and frames on a GPU."""
FAST = ("--render", "fast", "--fast-stride", "1", "--fast-confidence", "0.9")
"""The hour recipe's evaluation render (``fast s1 c0.9``), for ``sray eval`` and ``sray render`` alike."""


def _steps(ctx: CheckContext) -> int:
    """Training steps: 300 on a GPU; rank 0 dies at half of them."""
    return 4 if ctx.dry_run else 300


def train_arguments(ctx: CheckContext, shards: Path, root: Path, name: str) -> list[str]:
    """``sray train`` arguments: the recipe on ``shards``, one worker on the device, checkpoints every quarter."""
    steps, cuda = _steps(ctx), ctx.device.type == "cuda"
    sets = {"optim.steps": steps, "optim.warmup_2d_steps": steps // 4, "optim.warmup_steps": 0,
            "run.output_dir": root / "jobs", "run.ckpt_every": max(1, steps // 4), "run.val_every": steps,
            "run.log_every": max(1, steps // 10), "data.val_scenes": 1, "data.top_k": 6}
    if ctx.dry_run:
        sets |= {"model.n_source": ctx.views, "model.n_coarse": ctx.samples[0], "model.n_fine": ctx.samples[1],
                 "data.rays_per_batch": ctx.rays, "data.loader_workers": 0, "run.cpus_per_worker": 1}
    return ["train", "--recipe", RECIPE, "--data", str(shards), "--name", name, "--workers", "1",
            "--gpus-per-worker", "1" if cuda else "0", "--precision", "bf16" if cuda else "no",
            "--tracking-uri", f"sqlite:///{root / 'mlflow.db'}",
            *(a for key, value in sets.items() for a in ("--set", f"{key}={value}"))]


def _killed_and_resumed(ctx: CheckContext, arguments: list[str]) -> tuple[int, float]:
    """Run ``sray train`` with rank 0 killed at half the steps; (exit code, seconds)."""
    from sray.jobs.cli import main

    start = time.perf_counter()
    with mock.patch.dict(os.environ, {ENV_VAR: f"train.kill_at_step={max(2, _steps(ctx) // 2)}"}):
        code = main(arguments)
    return code, time.perf_counter() - start


def run(ctx: CheckContext) -> StageResult:
    """Train (killed and resumed), evaluate and render with the trained weights; refuse a shared GPU."""
    if skipped := skipped_without(FULL_STACK, "the Ray stage needs the full stack"):
        return skipped
    from sray.jobs.cli import main
    from sray.platform.checkpoints.folders import read_meta, resolve_checkpoint

    root = ctx.out / "ray"
    shards = make_world(toy_world(ctx.dry_run), root, progress=False)
    name = f"gpu-check-{time.strftime('%Y%m%d-%H%M%S')}"
    arguments = train_arguments(ctx, shards, root, name)
    code, train_s = _killed_and_resumed(ctx, arguments)
    job = root / "jobs" / name
    checkpoint = resolve_checkpoint(job)
    step, killed = int(read_meta(checkpoint)["step"]), (job / KILL_MARKER).exists()
    precision = arguments[arguments.index("--precision") + 1]
    rows = [[f"sray train, rank 0 killed at step {max(2, _steps(ctx) // 2)}, resumed",
             precision, f"{step} steps", f"{train_s:.0f}", str(checkpoint)]]
    device = ctx.device.type
    n_source = str(ctx.views)
    scene = unseen_scenes(shards)[0]
    eval_out, render_out = root / "eval", root / "render"
    eval_code = main(["eval", "--checkpoint", str(checkpoint), "--data", str(shards), "--n-source", n_source,
                      *FAST, "--out", str(eval_out), "--device", device,
                      "--tracking-uri", f"sqlite:///{root / 'mlflow.db'}"])
    metrics = json.loads((eval_out / "metrics.json").read_text())
    views = sum(len(s["views"]) for s in metrics["scenes"].values())
    rows.append(["sray eval (fast s1 c0.9, trained weights)", "fp32", f"{views} views", f"{metrics['wall_s']:.1f}",
                 f"{views / metrics['wall_s']:.2f} views/s"])
    size, n_frames = ("80x60", 4) if ctx.dry_run else (RENDER_SIZE, RENDER_FRAMES)
    render_code = main(["render", "--checkpoint", str(checkpoint), "--data", str(shards), "--scene", scene,
                        "--size", size, "--frames", str(n_frames), *FAST,
                        "--n-source", n_source, "--out", str(render_out), "--device", device, "--no-track"])
    frames = json.loads(next(render_out.rglob("frames.json")).read_text())
    rows.append([f"sray render {size} fly-through (fast s1 c0.9, trained weights)",
                 "fp32", f"{frames['n_frames']} frames", f"{frames['n_frames'] / frames['frames_per_s']:.1f}",
                 f"{frames['frames_per_s']:.2f} frames/s"])
    refused, shared_row = shared_gpu_request(shards, root, name, precision)
    rows.append(shared_row)
    ok = code == 0 and eval_code == 0 and render_code == 0 and killed and step == _steps(ctx) and refused
    summary = (f"sray train: {step} of {_steps(ctx)} steps in {train_s:.0f} s, "
               + ("killed and resumed" if killed else "NOT killed") + f"; sray eval {rows[1][4]}; "
               f"sray render {rows[2][4]}; 2 workers on one GPU " + ("refused" if refused else "NOT refused"))
    return StageResult("passed" if ok else "failed", summary, rows=rows,
                       header=["command", "precision", "work", "seconds", "result"])


def shared_gpu_request(shards: Path, root: Path, name: str, precision: str) -> tuple[bool, list[str]]:
    """(refused before Ray started, table row) of the recipe on 2 workers of 0.5 GPU (any sizes: refused first)."""
    from sray.platform.train.launcher import launch_training

    cfg = get_recipe(RECIPE)
    cfg.data.shards, cfg.run.output_dir, cfg.run.name = str(shards), str(root / "jobs"), f"{name}-shared-gpu"
    cfg.run.precision, cfg.run.tracking_uri = precision, f"sqlite:///{root / 'mlflow.db'}"
    cfg.run.workers, cfg.run.gpus_per_worker = 2, 0.5
    start = time.perf_counter()
    try:
        launch_training(cfg)
        refused, message = False, "ran: not refused"
    except InputError as err:
        refused, message = True, str(err)
    return refused, ["2 x 0.5 GPU", precision, "0 steps", f"{time.perf_counter() - start:.1f}", message]
