"""Stage ``fleet``: the finetune fleet with fractional GPUs. One S-Ray scene task alone on the GPU, then
``SHARING`` scene tasks at once on it (``1 / SHARING`` GPU each): training seconds per scene against the task
alone, the fleet's wall time and each task's peak GPU memory. A dry run shares the CPUs between
``DRY_RUN_SHARING`` tasks instead. Skipped, with the reason, where Ray, MLflow or webdataset are not installed."""

from __future__ import annotations

import time
from pathlib import Path

from sray.data_tools.shards.manifest import unseen_scenes
from sray.data_tools.synth.world import World, make_world
from sray.platform.config.fleet_config import FleetConfig
from sray.platform.config.recipes import get_recipe
from sray.platform.train.state import write_initial_checkpoint

from .context import CheckContext, has_module
from .report import StageResult

NEEDS = ("ray", "mlflow", "webdataset")
SHARING = 4
"""Scene tasks sharing the one GPU in the shared run."""
DRY_RUN_SHARING = 2
"""Scene tasks sharing the CPUs in a dry run (one CPU each, as on a 2-core machine: the dry run stays within a
minute)."""


def _shards(ctx: CheckContext, root: Path) -> Path:
    """``SHARING`` unseen procedural scenes (and one train scene), sharded with their neighbours."""
    hw = (32, 40) if ctx.dry_run else (120, 160)
    world = World(train_scenes=1, test_scenes=SHARING, views=20, height=hw[0], width=hw[1], seed=0, neighbours=8)
    return make_world(world, root, progress=False)


def _checkpoint(ctx: CheckContext, root: Path, shards: Path) -> Path:
    """A step-0 shared checkpoint of the ``synth-small`` network at this run's sizes (timing needs no
    pretraining; the fleet reads it as any other checkpoint)."""
    cfg = get_recipe("synth-small")
    cfg.model.n_source, (cfg.model.n_coarse, cfg.model.n_fine) = min(ctx.views, 4), ctx.samples
    cfg.data.shards, cfg.data.top_k = str(shards), 6
    return write_initial_checkpoint(cfg, root / "checkpoint" / "checkpoints" / "step_000000000")


def _fleet(ctx: CheckContext, out: Path, checkpoint: Path, shards: Path, scenes: list[str]) -> tuple[float, list]:
    """Run the fleet on ``scenes`` at once, each task with ``1 / len(scenes)`` of the device; (wall s, results)."""
    from sray.platform.finetune.fleet import run_fleet

    share = 1.0 / len(scenes)
    cuda = ctx.device.type == "cuda"
    cfg = FleetConfig(max_parallel=len(scenes), retries=0, cpus_per_task=1.0, gpus_per_task=share if cuda else 0.0)
    ft = cfg.finetune
    ft.max_steps, ft.eval_every, ft.patience = (2, 2, 1) if ctx.dry_run else (200, 100, 2)
    ft.held_out.n_source, ft.held_out.stride, ft.precision = min(ctx.views, 4), 4, "bf16" if cuda else "no"
    start = time.perf_counter()
    results = run_fleet(cfg, checkpoint, shards, scenes, out, f"sqlite:///{out / 'mlflow.db'}", ["sray"])
    return time.perf_counter() - start, results


def _mean(results: list, key: str) -> float:
    """Mean of one numeric result field over a fleet's results."""
    return sum(r[key] for r in results) / len(results)


def _row(name: str, wall: float, results: list) -> list[str]:
    """One table row: tasks, share of the device, fleet wall s, mean training s per scene, peak GPU MiB."""
    peaks = [r["gpu_peak_bytes"] for r in results if r["gpu_peak_bytes"]]
    peak = f"{max(peaks) / 2**20:.0f}" if peaks else "- (CPU)"
    return [name, str(len(results)), f"1/{len(results)}", f"{wall:.1f}", f"{_mean(results, 'steps_used'):.0f}",
            f"{_mean(results, 'wall_s'):.2f}", peak]


def run(ctx: CheckContext) -> StageResult:
    """One task alone, then ``SHARING`` tasks sharing the device; every task must finish."""
    missing = [m for m in NEEDS if not has_module(m)]
    if missing:
        return StageResult("skipped", f"{', '.join(missing)} not installed here: the fleet stage needs the full stack")
    root = ctx.out / "fleet"
    shards = _shards(ctx, root)
    checkpoint = _checkpoint(ctx, root, shards)
    scenes = unseen_scenes(shards)[:DRY_RUN_SHARING if ctx.dry_run else SHARING]
    stamp = time.strftime("%Y%m%d-%H%M%S")
    alone_wall, alone = _fleet(ctx, root / f"alone-{stamp}", checkpoint, shards, scenes[:1])
    shared_wall, shared = _fleet(ctx, root / f"shared-{stamp}", checkpoint, shards, scenes)
    failed = [f"{r['scene']}: {r['error']}" for r in alone + shared if r["status"] != "finished"]
    if failed:
        return StageResult("failed", "; ".join(failed)[:300])
    rows = [_row("one task alone", alone_wall, alone), _row(f"{len(scenes)} tasks sharing", shared_wall, shared)]
    alone_s, shared_s = _mean(alone, "wall_s"), _mean(shared, "wall_s")
    summary = (f"{len(scenes)} tasks on one {'GPU' if ctx.device.type == 'cuda' else 'CPU set'}: "
               f"{shared_s:.2f} s training per scene against {alone_s:.2f} s alone "
               f"({shared_s / max(alone_s, 1e-9):.2f}x); fleet wall {shared_wall:.0f} s against "
               f"{alone_wall:.0f} s for one task")
    return StageResult("passed", summary, rows=rows,
                       header=["run", "tasks", "device share each", "fleet wall s", "steps per scene",
                               "training s per scene", "peak GPU MiB per task"])
