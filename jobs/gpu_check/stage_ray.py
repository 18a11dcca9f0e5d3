"""Stage ``ray``: ``sray train`` with one (GPU) worker through Ray Train, Accelerate and MLflow, on
procedural shards, and two Train workers asking for one GPU between them (refused before Ray starts: NCCL
refuses two ranks on one GPU). Skipped, with the reason, where Ray, MLflow or webdataset are not installed."""

from __future__ import annotations

import copy
import time
from typing import TYPE_CHECKING

from sray.data_tools.synth.world import World, make_world
from sray.platform.config.recipes import get_recipe
from sray.platform.train.inputs import InputError

from .context import CheckContext, has_module
from .report import StageResult

if TYPE_CHECKING:
    from sray.platform.config.train_config import TrainConfig

NEEDS = ("ray", "mlflow", "webdataset")


def run(ctx: CheckContext) -> StageResult:
    """A short training job on one worker (the GPU on CUDA); its steps, rays/s and checkpoint."""
    missing = [m for m in NEEDS if not has_module(m)]
    if missing:
        return StageResult("skipped", f"{', '.join(missing)} not installed here: the Ray stage needs the full stack")
    from sray.platform.train.launcher import launch_training

    root = ctx.out / "ray"
    hw = (32, 40) if ctx.dry_run else (120, 160)
    world = World(train_scenes=2, test_scenes=1, views=20, height=hw[0], width=hw[1], seed=0, neighbours=8)
    shards = make_world(world, root, progress=False)
    cfg = get_recipe("synth-small")
    steps = 2 if ctx.dry_run else 100
    cfg.model.n_source, (cfg.model.n_coarse, cfg.model.n_fine) = min(ctx.views, 4), ctx.samples
    cfg.data.shards, cfg.data.top_k, cfg.data.rays_per_batch = str(shards), 6, ctx.rays
    cfg.data.loader_workers, cfg.data.val_views_per_scene = 0, 1
    cfg.optim.steps = steps
    cfg.run.workers, cfg.run.gpus_per_worker = 1, (1.0 if ctx.device.type == "cuda" else 0.0)
    cfg.run.precision = "bf16" if ctx.device.type == "cuda" else "no"
    cfg.run.output_dir, cfg.run.tracking_uri = str(root / "jobs"), f"sqlite:///{root / 'mlflow.db'}"
    cfg.run.val_every = cfg.run.ckpt_every = steps
    cfg.run.register_model, cfg.run.name = "", f"gpu-check-{time.strftime('%Y%m%d-%H%M%S')}"
    start = time.perf_counter()
    outcome = launch_training(cfg)
    seconds = time.perf_counter() - start
    ok = outcome.latest_checkpoint is not None
    row = [f"{cfg.run.workers} x {'GPU' if cfg.run.gpus_per_worker else 'CPU'}", cfg.run.precision, str(steps),
           f"{seconds:.0f}", str(outcome.latest_checkpoint)]
    refused, shared_row = shared_gpu_request(cfg)
    summary = (f"sray train: {steps} steps in {seconds:.0f} s (Ray start-up included)"
               + ("" if ok else ", no checkpoint written")
               + ("; 2 workers on one GPU refused in " + shared_row[3] + " s" if refused else
                  "; 2 workers on one GPU were NOT refused"))
    return StageResult("passed" if ok and refused else "failed", summary,
                       header=["workers", "precision", "steps", "seconds", "checkpoint or message"],
                       rows=[row, shared_row])


def shared_gpu_request(cfg: TrainConfig) -> tuple[bool, list[str]]:
    """Launch ``cfg`` with 2 workers of 0.5 GPU (both would land on one GPU, which NCCL refuses): whether it was
    refused before Ray started, and the table row (time to the refusal, its message)."""
    from sray.platform.train.launcher import launch_training

    shared = copy.deepcopy(cfg)
    shared.run.workers, shared.run.gpus_per_worker = 2, 0.5
    shared.run.name = f"{cfg.run.name}-shared-gpu"
    start = time.perf_counter()
    try:
        launch_training(shared)
        refused, message = False, "ran: not refused"
    except InputError as err:
        refused, message = True, str(err)
    return refused, ["2 x 0.5 GPU", cfg.run.precision, "0", f"{time.perf_counter() - start:.1f}", message]
