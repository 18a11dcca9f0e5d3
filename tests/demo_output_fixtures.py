"""A finished ``sray demo --out`` folder made by hand with known numbers, in the layout ``sray.jobs.demo`` writes: its
training job (a mid-run checkpoint the evaluation scored, the last one holding the counters), the zero-shot
``eval/metrics.json``, the fleet's ``fleet.json`` and ``fleet_results.json`` and the fly-through's ``frames.json``; the
files' modification times span :data:`DEMO_WALL_S`.

Use from a test module (the tests folder is not a package)::

    from demo_output_fixtures import write_demo_output
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from train_fixtures import tiny_config

from sray.data_tools.shards.manifest import read_manifest, unseen_scenes
from sray.platform.checkpoints.folders import write_checkpoint
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.train.state import build_training, training_state

JOB = "synth-demo-20261207-120000"
"""The demo's training job, named as ``launch_training`` names an unnamed job of the recipe."""
COUNTERS = {"cpu_seconds": 300.0, "wall_seconds": 240.0, "peak_memory_mb": 1200.0}
"""The last checkpoint's counters (the mid-run one holds half of each)."""
ZERO_SHOT = {"miou": 0.25, "total_acc": 0.7, "class_avg_acc": 0.4}
"""The zero-shot evaluation's dataset-level mean scores (shares)."""
FLEET = {"sray": (0.30, 0.83), "semantic-nerf": (0.0, 0.17), "sray-rgbd": (0.31, 0.81), "2d-transfer": (0.5, 0.82)}
"""Method -> held-out mIoU before and after its finetune, in the fleet's order."""
FRAMES_PER_S = 2.5
DEMO_WALL_S = 470.5
"""Seconds from the demo's first output file to its last."""


def _json(path: Path, data: object) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))


def _result(scene: str, method: str, before: float, after: float, budget_s: float, protocol: dict) -> dict:
    """A finished fleet pair (docs/CONTRACTS.md, "Fleet results") stopped by a ``budget_s`` wall budget."""
    curve = [{"step": 0, "wall_s": 0.0, "miou": before}, {"step": 25, "wall_s": 0.6 * budget_s, "miou": after},
             {"step": 40, "wall_s": budget_s + 0.4, "miou": after - 0.01}]
    return {"scene": scene, "method": method, "status": "finished", "error": None, "attempts": 1, "steps_used": 40,
            "max_steps": 300, "stopped_early": False, "stop_reason": "max_seconds", "wall_s": budget_s + 0.4,
            "cpu_s": 2 * budget_s, "miou_before": before, "miou_after": after, "psnr_after": 20.0,
            "artifact_bytes": 1000, "full_checkpoint_bytes": 10000, "child_run_id": None, "protocol": protocol,
            "curve": curve, "node_id": None, "gpu_peak_bytes": None}


def write_demo_output(out: Path, shards: Path, seed: int = 0, scale: float = 1.0, budget_s: float = 60.0) -> Path:
    """Write the folder ``out`` of a demo of seed ``seed`` on ``shards`` whose counters and scores are the module's
    times ``scale``, its fleet run at ``budget_s`` seconds per room; returns ``out``."""
    cfg = tiny_config(shards, out)
    cfg.recipe, cfg.optim.steps, cfg.optim.warmup_2d_steps, cfg.run.seed = "synth-demo", 600, 200, seed
    model, optimizer, scheduler = build_training(cfg)
    job = out / "train" / JOB / "checkpoints"
    for step, share in ((300, 0.5), (600, 1.0)):
        counters = {k: v * scale * share for k, v in COUNTERS.items()} | {"skipped_steps": 0}
        write_checkpoint(training_state(model.net, optimizer, scheduler, None, step, cfg, None, counters),
                         job / f"step_{step:09d}", step)
    scored = job / "step_000000300"  # the best checkpoint, as the demo evaluates it
    protocol = EvalProtocol.from_shards(shards, 4, 2).to_json()
    classes = len(next(iter(read_manifest(shards).scenes.values())).meta["class_names"])
    means = {k: v * scale for k, v in ZERO_SHOT.items()}
    _json(out / "eval" / "metrics.json", {
        "checkpoint": str(scored), "checkpoint_step": 300, "shards": str(Path(shards).resolve()), "protocol": protocol,
        "scenes": {s: {"dataset_level": {**means, "iou_per_class": [0.5, None] + [0.1] * (classes - 2)}}
                   for s in unseen_scenes(shards)},
        "mean": {"dataset_level": means, "n_views": 4}})
    _json(out / "fleet" / "fleet.json", {"format": "sray-fleet", "checkpoint": str(scored.resolve())})
    _json(out / "fleet" / "fleet_results.json", [
        _result("synth_test_000", m, b * scale, a * scale, budget_s, protocol) for m, (b, a) in FLEET.items()])
    _json(out / "render" / "frames.json", {"frames_per_s": FRAMES_PER_S / scale, "n_frames": 24,
                                           "size": {"height": 120, "width": 160},
                                           "protocol_line": "sources: 8 per query; render: fast"})
    files = sorted(p for p in out.rglob("*") if p.is_file())
    start = 1.8e9
    for i, path in enumerate(files):  # the first file at the start, the fleet's results last
        os.utime(path, (start, start + (DEMO_WALL_S * scale if path.name == "fleet_results.json" else i)))
    return out
