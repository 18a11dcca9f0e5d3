"""Stage ``fleet``: ``sray finetune-fleet`` with fractional GPUs: one S-Ray task alone, then ``SHARING`` scenes x
``METHODS`` with ``SHARING`` tasks at once: seconds per scene against alone, fleet wall time, peak GPU memory."""

from __future__ import annotations

import time
from pathlib import Path

from sray.data_tools.shards.manifest import unseen_scenes
from sray.data_tools.synth.world import make_world
from sray.platform.config.fleet_config import FleetConfig
from sray.platform.config.recipes import get_recipe
from sray.platform.train.state import write_initial_checkpoint

from .context import FULL_STACK, CheckContext, skipped_without
from .report import StageResult
from .synthetic import toy_world

SHARING = 4
METHODS = ("sray", "semantic-nerf", "2d-transfer")
DRY_RUN_SHARING = 2
"""Scene tasks sharing the CPUs in a dry run (one CPU each, as on a 2-core machine)."""


def _checkpoint(ctx: CheckContext, root: Path, shards: Path) -> Path:
    """A step-0 checkpoint of the GPU recipe's network at this run's sizes (timing needs no pretraining)."""
    cfg = get_recipe("synth-gpu-minutes")
    cfg.model.n_source, (cfg.model.n_coarse, cfg.model.n_fine) = min(ctx.views, 4), ctx.samples
    cfg.data.shards, cfg.data.top_k = str(shards), 6
    return write_initial_checkpoint(cfg, root / "checkpoint" / "checkpoints" / "step_000000000")


def _fleet(ctx: CheckContext, out: Path, checkpoint: Path, shards: Path, scenes: list[str],
           methods: list[str], segmenter: Path) -> tuple[float, list]:
    """(wall s, results) of the fleet's ``methods`` on ``scenes``, all at once, each with its share of the device."""
    from sray.platform.finetune.fleet import run_fleet

    share = 1.0 / len(scenes)
    cuda = ctx.device.type == "cuda"
    cfg = FleetConfig(max_parallel=len(scenes), retries=0, cpus_per_task=1.0, gpus_per_task=share if cuda else 0.0)
    cfg.transfer.segmenter = str(segmenter)
    ft = cfg.finetune
    ft.max_steps, ft.eval_every, ft.patience = (2, 2, 1) if ctx.dry_run else (100, 50, 2)
    if ctx.dry_run:  # a toy Semantic-NeRF: the paper's 8 x 256 MLP takes most of a CPU dry run's time
        cfg.nerf.depth, cfg.nerf.width, cfg.nerf.skip_layer = 2, 32, None
    ft.held_out.n_source, ft.held_out.stride, ft.precision = min(ctx.views, 4), 4, "bf16" if cuda else "no"
    start = time.perf_counter()
    results = run_fleet(cfg, checkpoint, shards, scenes, out, f"sqlite:///{out / 'mlflow.db'}", methods)
    return time.perf_counter() - start, results


def _mean(results: list, key: str) -> float:
    return sum(r[key] for r in results) / len(results)


def _row(name: str, share: int, wall: float, results: list) -> list[str]:
    """One table row: tasks, share of the device, fleet wall s, mean steps and training s per scene, peak GPU MiB."""
    peaks = [r["gpu_peak_bytes"] for r in results if r["gpu_peak_bytes"]]
    peak = f"{max(peaks) / 2**20:.0f}" if peaks else "- (CPU)"
    return [name, str(len(results)), f"1/{share}", f"{wall:.1f}", f"{_mean(results, 'steps_used'):.0f}",
            f"{_mean(results, 'wall_s'):.2f}", peak]


def run(ctx: CheckContext) -> StageResult:
    """One task alone, then ``SHARING`` tasks sharing the device; every task must finish."""
    if skipped := skipped_without(FULL_STACK, "the fleet stage needs the full stack"):
        return skipped
    from sray.platform.eval.segmenter import segmenter_from_checkpoint

    root = ctx.out / "fleet"
    shards = make_world(toy_world(ctx.dry_run, train_scenes=1, test_scenes=SHARING), root, progress=False)
    checkpoint = _checkpoint(ctx, root, shards)
    segmenter = root / "segmenter"
    segmenter_from_checkpoint(checkpoint, segmenter)  # 2d-transfer starts from the checkpoint's encoder and head
    scenes = unseen_scenes(shards)[:DRY_RUN_SHARING if ctx.dry_run else SHARING]
    stamp = time.strftime("%Y%m%d-%H%M%S")
    alone_wall, alone = _fleet(ctx, root / f"alone-{stamp}", checkpoint, shards, scenes[:1], ["sray"], segmenter)
    shared_wall, shared = _fleet(ctx, root / f"shared-{stamp}", checkpoint, shards, scenes, list(METHODS), segmenter)
    failed = [f"{r['scene']}/{r['method']}: {r['error']}" for r in alone + shared if r["status"] != "finished"]
    if failed:
        return StageResult("failed", "; ".join(failed)[:300])
    rows = [_row("S-Ray, one task alone", 1, alone_wall, alone)]
    ran = dict.fromkeys(r["method"] for r in shared)  # METHODS, and the fleet's RGB-D twin of S-Ray beside them
    rows += [_row(f"{method}, {len(scenes)} scenes sharing", len(scenes), shared_wall,
                  [r for r in shared if r["method"] == method]) for method in ran]
    alone_s = _mean(alone, "wall_s")
    shared_s = _mean([r for r in shared if r["method"] == "sray"], "wall_s")
    summary = (f"{len(scenes)} scenes x {len(ran)} methods, {len(scenes)} tasks at once on one "
               f"{'GPU' if ctx.device.type == 'cuda' else 'CPU set'}: S-Ray {shared_s:.2f} s training per scene "
               f"against {alone_s:.2f} s alone ({shared_s / max(alone_s, 1e-9):.2f}x); fleet wall {shared_wall:.0f} s "
               f"against {alone_wall:.0f} s for one task")
    return StageResult("passed", summary, rows=rows,
                       header=["method, run", "tasks", "device share each", "fleet wall s", "steps per scene",
                               "training s per scene", "peak GPU MiB per task"])
