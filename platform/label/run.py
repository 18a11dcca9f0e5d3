"""``sray label``'s whole job (docs/capture.md): per chosen scene, its label files and a spline fly-through under
``OUT/<scene>/``, tracked (metrics ``<scene>/miou``, ...; labels.json and fly-through files under ``<scene>/``)."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import read_manifest
from sray.platform.common.progress import make_progress
from sray.platform.label.labeller import Labeller
from sray.platform.label.scene_labels import LABELS_FILE, label_scene
from sray.platform.render.flythrough import Flythrough
from sray.platform.render.plan import plan_flythrough
from sray.platform.render.tracked import log_flythrough
from sray.platform.tracking.registry import DEFAULT_TRACKER, get_tracker
from sray.platform.tracking.tracker import RunLogger


def chosen_scenes(shards: Path, scenes: list[str] | None) -> list[str]:
    """``scenes`` checked against the manifest (ValueError naming the unknown ones), or every scene when None."""
    manifest = read_manifest(Path(shards))
    if scenes is None:
        return sorted(manifest.scenes)
    unknown = [s for s in scenes if s not in manifest.scenes]
    if unknown or not scenes:
        raise ValueError(f"{Path(shards) / 'manifest.json'}: field 'scenes' has no scene {unknown or scenes}; known: "
                         f"{', '.join(sorted(manifest.scenes)[:10])}")
    return list(scenes)


def label_scenes(labeller: Labeller, shards: Path, scenes: list[str], out: Path, fly_frames: int,
                 logger: RunLogger | None = None, progress: bool = True) -> dict[str, Any]:
    """Label and fly through ``scenes`` (``fly_frames`` 0: none) into ``out``; per scene its record + ``flythrough``."""
    manifest = read_manifest(Path(shards))
    total = sum(len(manifest.scenes[s].meta["view_ids"]) for s in scenes)
    bar = make_progress(progress, total=total, desc="sray label")
    results: dict[str, Any] = {}
    for step, scene in enumerate(scenes):
        bar.set_postfix(scene=scene)
        record = label_scene(labeller, shards, manifest, scene, out / scene, lambda _i: bar.update(1))
        if fly_frames > 0:
            pool = source_pool(SceneMeta.from_json(manifest.scenes[scene].meta))
            plan = plan_flythrough(shards, scene, path="spline", n_frames=fly_frames)
            fly = Flythrough(labeller.net, plan, min(labeller.n_source, len(pool)), labeller.fast, labeller.runtime)
            record["flythrough"] = fly.render(out / scene / "flythrough", labeller.device, about=labeller.about,
                                              label="sray label", progress=progress)["files"]
        if logger is not None:
            if "scores" in record:
                logger.log_metrics({f"{scene}/{k}": record["scores"][k]
                                    for k in ("miou", "total_acc", "class_avg_acc")}, step)
            logger.log_artifact(out / scene / LABELS_FILE, scene)
            log_flythrough(logger, record.get("flythrough", {}), f"{scene}/flythrough")
        results[scene] = record
    bar.close()
    return results


def tracked_labels(labeller: Labeller, shards: Path, scenes: list[str], out: Path, fly_frames: int, *,
                   tracker: str = DEFAULT_TRACKER, tracking_uri: str = "", experiment: str = "sray-label",
                   progress: bool = True) -> dict[str, Any]:
    """:func:`label_scenes` inside a new run of ``tracker``; returns its result plus ``run`` (the handle's fields)."""
    tracking = get_tracker(tracker, tracking_uri)
    run = tracking.start_run(experiment, f"label-{time.strftime('%Y%m%d-%H%M%S')}",
                             tags={"sray.kind": "label", "sray.checkpoint": labeller.about.get("checkpoint", "")})
    with tracking.logger(run) as logger:
        logger.log_params({**labeller.about, "shards": str(shards), "scenes": ",".join(scenes), "out": str(out),
                           "n_source": labeller.n_source, "render": "fast" if labeller.fast else "full",
                           "flythrough_frames": fly_frames})
        results = label_scenes(labeller, shards, scenes, out, fly_frames, logger, progress)
    return {"scenes": results, "run": dataclasses.asdict(run)}
