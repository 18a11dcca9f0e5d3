"""Stage ``ray``: ``sray train`` with one (GPU) worker through Ray Train, Accelerate and MLflow, on
procedural shards. Skipped, with the reason, where Ray, MLflow or webdataset are not installed."""

from __future__ import annotations

import time

from .context import CheckContext, has_module
from .report import StageResult

NEEDS = ("ray", "mlflow", "webdataset")


def run(ctx: CheckContext) -> StageResult:
    """A short training job on one worker (the GPU on CUDA); its steps, rays/s and checkpoint."""
    missing = [m for m in NEEDS if not has_module(m)]
    if missing:
        return StageResult("skipped", f"{', '.join(missing)} not installed here: the Ray stage needs the full stack")
    from sray.data_tools.shards.writer import write_shards
    from sray.data_tools.synth.dataset import generate_dataset
    from sray.jobs.recipes import get_recipe
    from sray.platform.train.launcher import launch_training

    root = ctx.out / "ray"
    hw = (32, 40) if ctx.dry_run else (120, 160)
    generate_dataset(root / "scenes", n_train=2, n_test=1, n_views=20, height=hw[0], width=hw[1], seed=0,
                     progress=False)
    write_shards(root / "scenes", root / "shards", neighbours=8, progress=False)
    cfg = get_recipe("synth-small")
    steps = 2 if ctx.dry_run else 100
    cfg.model.n_source, (cfg.model.n_coarse, cfg.model.n_fine) = min(ctx.views, 4), ctx.samples
    cfg.data.shards, cfg.data.top_k, cfg.data.rays_per_batch = str(root / "shards"), 6, ctx.rays
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
    return StageResult("passed" if ok else "failed",
                       f"sray train: {steps} steps in {seconds:.0f} s (Ray start-up included)"
                       + ("" if ok else ", no checkpoint written"),
                       header=["workers", "precision", "steps", "seconds", "checkpoint"], rows=[row])
