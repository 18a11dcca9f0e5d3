"""A fly-through as a tracked run (``sray render``): request and protocol as params, the protocol line as the
``sray.protocol`` tag, the render rate as metrics, every output file as an artifact under ``flythrough/``."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import torch

from sray.platform.render.flythrough import Flythrough
from sray.platform.tracking.registry import DEFAULT_TRACKER, get_tracker
from sray.platform.tracking.tracker import RunLogger

ARTIFACT_PATH = "flythrough"  # artifact folder of a fly-through's files in its run


def log_flythrough(logger: RunLogger, files: dict[str, str], artifact_path: str = ARTIFACT_PATH) -> None:
    """Store a fly-through's output files (``Flythrough.render``'s ``files``) under ``artifact_path``."""
    for path in files.values():
        logger.log_artifact(Path(path), artifact_path)


def tracked_flythrough(fly: Flythrough, out_dir: Path, device: torch.device, *, about: dict[str, str], label: str,
                       tracker: str = DEFAULT_TRACKER, tracking_uri: str = "", experiment: str = "sray-render",
                       progress: bool = True) -> dict[str, Any]:
    """Render ``fly`` into ``out_dir`` inside a new run of ``tracker``; ``about``: what made the model
    (``{"checkpoint", "artifact"?}``). Returns ``Flythrough.render``'s dict plus ``run`` (the run handle's fields)."""
    tracking = get_tracker(tracker, tracking_uri)
    plan = fly.plan
    kind = "finetuned" if "artifact" in about else "zero-shot"
    run = tracking.start_run(experiment, f"render-{plan.meta.name}-{kind}-{time.strftime('%Y%m%d-%H%M%S')}",
                             tags={"sray.kind": "render", "sray.scene": plan.meta.name,
                                   "sray.checkpoint": about["checkpoint"], "sray.protocol": fly.protocol.describe()})
    with tracking.logger(run) as logger:
        logger.log_params({**about, "scene": plan.meta.name, "shards": str(plan.shards), "path": plan.path.describe,
                           "frames": len(plan.path), "height": plan.path.hw[0], "width": plan.path.hw[1],
                           "fps": plan.fps, "protocol": fly.protocol.to_json()})
        result = fly.render(out_dir, device, about=about, label=label, progress=progress)
        logger.log_metrics({"render/frames_per_s": result["frames_per_s"], "render/n_frames": result["n_frames"]}, 0)
        log_flythrough(logger, result["files"])
    return result | {"run": dataclasses.asdict(run)}
