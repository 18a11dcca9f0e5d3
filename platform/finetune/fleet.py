"""The finetune fleet driver (``sray finetune-fleet``): one Ray task per (scene, method), re-run after a back-off when
it fails, one parent tracked run. Paths handed to tasks are absolute: on a cluster they must be on shared storage."""

from __future__ import annotations

import dataclasses
import json
import logging
import time
from pathlib import Path
from typing import Any

import ray

from sray.data_tools.atomic import atomic_write_json, atomic_write_text
from sray.data_tools.shards.manifest import read_manifest
from sray.platform.checkpoints.folders import resolve_checkpoint
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.common.fault_hook import error_text, propagated_env
from sray.platform.common.progress import progress_env
from sray.platform.common.ray_address import check_ray_address
from sray.platform.config.fleet_config import FleetConfig, check_fleet_config
from sray.platform.config.stored_format import outdated
from sray.platform.finetune.fleet_report import results_table, summary_metrics
from sray.platform.finetune.methods.registry import METHODS, get_method, method_names, with_depth_twins
from sray.platform.finetune.scene_artifacts import checkpoint_sha256, model_bytes, state_file
from sray.platform.finetune.scene_finetune import RESULT_FILE, SceneTask, run_scene_task, write_result
from sray.platform.tracking.registry import get_tracker
from sray.platform.tracking.tracker import RunHandle, Tracker
from sray.platform.train.launcher import init_ray
from sray.platform.train.resources import check_feasible
from sray.platform.viz.charts import write_fleet_charts

log = logging.getLogger(__name__)

FLEET_FILE = "fleet.json"
"""``<out_dir>/fleet.json``: the base checkpoint's checksum and the parent run, for re-launches."""


def _say(msg: str) -> None:
    print(f"[fleet] {msg}", flush=True)


def result_dir(out_dir: Path, scene: str, method: str) -> Path:
    """``<out_dir>/scenes/<scene>/<method>``: a pair's result.json and artifact."""
    return Path(out_dir) / "scenes" / scene / method


def read_result(out_dir: Path, scene: str, method: str) -> dict[str, Any] | None:
    """A pair's result.json, or None when there is none (or it is unreadable: then it is re-run)."""
    path = result_dir(out_dir, scene, method) / RESULT_FILE
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as e:
        log.warning("%s is unreadable (%s); the pair runs again", path, e)
        return None


def failed_result(task: SceneTask, error: str, full_bytes: int | None) -> dict[str, Any]:
    """The contract's result dict of a pair whose last attempt failed (nothing measured)."""
    return {"scene": task.scene, "method": task.method, "status": "failed", "error": error, "attempts": task.attempt,
            "steps_used": 0, "max_steps": task.config.finetune.max_steps, "stopped_early": False, "stop_reason": None,
            "wall_s": 0.0, "cpu_s": 0.0, "miou_before": None, "miou_after": None, "psnr_after": None,
            "artifact_bytes": None, "full_checkpoint_bytes": full_bytes,
            "child_run_id": task.run.run_id if task.run else None, "protocol": None, "curve": [], "node_id": None,
            "gpu_peak_bytes": None}


def _validate(shards: Path, scenes: list[str], methods: list[str]) -> None:
    """ValueError naming what is wrong with the request, before anything starts."""
    known = method_names()
    bad = [m for m in methods if m not in known]
    if bad or not methods:
        raise ValueError(f"methods {bad or methods}: use one or more of {', '.join(known)}")
    if not scenes:
        raise ValueError(f"no scenes to finetune; name them or use every test scene of {shards}")
    manifest = read_manifest(shards)
    for scene in scenes:
        entry = manifest.scenes.get(scene)
        if entry is None:
            raise ValueError(f"{shards}/manifest.json: no scene {scene!r}; known: {sorted(manifest.scenes)[:10]}")
        if not entry.meta.get("splits", {}).get("test"):
            raise ValueError(f"{shards}/manifest.json: scene {scene!r} has no held-out 'test' views to validate on")


def _fleet_record(out_dir: Path, base_sha256: str, tracker: Tracker) -> dict[str, Any]:
    """The fleet's record (new, or a re-launch's); ValueError for another checkpoint's or an outdated fleet."""
    path = out_dir / FLEET_FILE
    if not path.exists():
        return {"format": "sray-fleet", "base_sha256": base_sha256, "tracker": tracker.name,
                "tracking_uri": tracker.store, "parent_run_id": None, "launches": 0}
    record = json.loads(path.read_text())
    if "tracker" not in record:  # written before trackers had names
        raise outdated(f"{path}: this fleet record", "1 (no tracker name)", 2)
    if record.get("base_sha256") != base_sha256:
        raise ValueError(f"{path}: field 'base_sha256' is {record.get('base_sha256')}, but this checkpoint's is "
                         f"{base_sha256}; this folder holds a fleet of another checkpoint: pass another --out")
    return record


def parent_run(tracker: Tracker, record: dict[str, Any], experiment: str, out_dir: Path) -> tuple[RunHandle, bool]:
    """(handle, whether new) of the parent run: the one ``record`` names (RUNNING again) if found, else a new one."""
    if record.get("parent_run_id") and (record["tracker"], record["tracking_uri"]) == (tracker.name, tracker.store):
        try:
            handle = tracker.get_run(record["parent_run_id"])
            tracker.set_status(handle, "RUNNING")
            return handle, False
        except Exception as e:  # noqa: BLE001 - deleted or unreachable: start a new parent
            log.warning("parent run %s not usable (%s); starting a new one", record["parent_run_id"], e)
    handle = tracker.start_run(experiment, f"fleet · {out_dir.parent.name}/{out_dir.name}",
                               tags={"sray.kind": "fleet", "sray.fleet_dir": str(out_dir)})
    return handle, True


def _charts(results: list[dict[str, Any]], out_dir: Path) -> list[Path]:
    """PNGs of ``sray.platform.viz.charts.write_fleet_charts`` ([] when drawing them fails)."""
    try:
        return [Path(p) for p in write_fleet_charts(results, out_dir / "charts", METHODS)]
    except Exception as e:  # noqa: BLE001 - the results are saved already; a chart bug must not lose them
        log.warning("fleet charts failed: %s", e, exc_info=True)
        return []


def _schedule(tasks: list[SceneTask], cfg: FleetConfig, full_bytes: int,
              tracker: Tracker) -> dict[tuple[str, str], dict[str, Any]]:
    """Run the tasks on Ray with the in-flight window, re-runs with back-off and failure reports."""
    remote_task = ray.remote(run_scene_task).options(num_cpus=cfg.cpus_per_task, num_gpus=cfg.gpus_per_task,
                                                     max_retries=0, retry_exceptions=False,
                                                     runtime_env={"env_vars": propagated_env() | progress_env()})
    waiting: list[tuple[float, SceneTask]] = [(0.0, task) for task in tasks]
    in_flight: dict[Any, SceneTask] = {}
    results: dict[tuple[str, str], dict[str, Any]] = {}
    try:
        while waiting or in_flight:
            now = time.monotonic()
            for item in sorted((w for w in waiting if w[0] <= now), key=lambda w: w[0]):
                if len(in_flight) >= cfg.max_parallel:
                    break
                waiting.remove(item)
                in_flight[remote_task.remote(item[1])] = item[1]
                _say(f"started {item[1].scene}/{item[1].method} (attempt {item[1].attempt})")
            next_ready = min((w[0] for w in waiting), default=None)
            if not in_flight:
                time.sleep(max(next_ready - time.monotonic(), 0.0))
                continue
            timeout = None if next_ready is None or len(in_flight) >= cfg.max_parallel else max(next_ready - now, 0.05)
            done, _ = ray.wait(list(in_flight), num_returns=1, timeout=timeout)
            for ref in done:
                task = in_flight.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception as e:  # noqa: BLE001 - a task error or a dead worker: re-run or report
                    error = error_text(getattr(e, "cause", None) or e)  # the exception inside a RayTaskError
                    if task.attempt <= cfg.retries:
                        delay = cfg.retry_backoff_s * 2 ** (task.attempt - 1)
                        waiting.append((time.monotonic() + delay, dataclasses.replace(task, attempt=task.attempt + 1)))
                        _say(f"{task.scene}/{task.method} attempt {task.attempt} failed ({error}); "
                             f"re-run in {delay:g} s")
                        continue
                    result = failed_result(task, error, full_bytes)
                    write_result(Path(task.out_dir), result)
                    if task.run:
                        tracker.tag_run(task.run, {"sray.status": "failed", "sray.error": str(e)})
                        tracker.end_run(task.run, "FAILED")
                    _say(f"{task.scene}/{task.method} FAILED after {task.attempt} attempts: {error}")
                else:
                    _say(f"{task.scene}/{task.method} finished: mIoU {result['miou_before']:.3f} -> "
                         f"{result['miou_after']:.3f} in {result['steps_used']} steps ({result['wall_s']:.1f} s)")
                results[(task.scene, task.method)] = result
    except KeyboardInterrupt:
        for ref in in_flight:
            ray.cancel(ref, force=True)
        for task in tasks:
            if task.run and (task.scene, task.method) not in results:
                tracker.end_run(task.run, "KILLED")
        raise
    return results


def run_fleet(cfg: FleetConfig, checkpoint: Path, shards: Path, scenes: list[str], out_dir: Path,
              tracking_uri: str, methods: list[str], clip_frames: int = 0) -> list[dict[str, Any]]:
    """Finetune every (scene, method) pair; their result dicts (docs/CONTRACTS.md), scenes-major. ``tracking_uri``:
    the store of ``cfg.tracker`` (empty: its default); ``clip_frames``: fly-through frames per S-Ray pair (0: none)."""
    check_fleet_config(cfg)
    if cfg.address:
        check_ray_address(cfg.address)
    tracker = get_tracker(cfg.tracker, tracking_uri)
    checkpoint, shards, out_dir = resolve_checkpoint(checkpoint), Path(shards).resolve(), Path(out_dir).resolve()
    scenes = list(dict.fromkeys(scenes))
    _validate(shards, scenes, list(methods))
    base, train_cfg = model_from_checkpoint(checkpoint)
    asked, methods = list(dict.fromkeys(methods)), with_depth_twins(list(methods), train_cfg.model.inputs)
    if added := [m for m in methods if m not in asked and get_method(m).given_depth_of]:
        _say(f"also running {', '.join(added)}: S-Ray given the source depth stands beside every method that reads it")
    for name in dict.fromkeys(methods):  # each method's own settings (2d-transfer's segmenter), before anything starts
        if (check := get_method(name).checked_config) is not None:
            cfg = check(cfg)
    base_sha = checkpoint_sha256(checkpoint)
    out_dir.mkdir(parents=True, exist_ok=True)
    record = _fleet_record(out_dir, base_sha, tracker)
    full_bytes = model_bytes(base)
    pairs = [(s, m) for s in scenes for m in methods]
    done = {p: r for p in pairs if (r := read_result(out_dir, *p)) is not None and r.get("status") == "finished"}
    if done:
        _say(f"skipping {len(done)} finished pair(s): " + ", ".join(f"{s}/{m}" for s, m in done))

    tracker.ensure_store()
    parent, is_new = parent_run(tracker, record, cfg.experiment, out_dir)
    record.update(parent_run_id=parent.run_id, tracker=tracker.name, tracking_uri=tracker.store,
                  launches=record["launches"] + 1, checkpoint=str(checkpoint), state_file=str(state_file(checkpoint)),
                  shards=str(shards))
    atomic_write_json(out_dir / FLEET_FILE, record)
    _say(f"parent {tracker.label} run: {parent.ui_url}" + (f"  ({parent.ui_hint})" if parent.ui_hint else ""))
    if len(done) < len(pairs):
        init_ray(cfg.address or None)
        check_feasible(1, cfg.cpus_per_task, cfg.gpus_per_task)
    tasks = []
    for scene, method in (p for p in pairs if p not in done):
        child = tracker.start_run(cfg.experiment, f"{scene} · {method}", parent=parent,
                                  tags={"sray.kind": "fleet-scene", "sray.scene": scene, "sray.method": method})
        tasks.append(SceneTask(scene=scene, method=method, checkpoint=str(checkpoint), base_sha256=base_sha,
                             shards=str(shards), out_dir=str(result_dir(out_dir, scene, method)),
                             run=child, attempt=1, config=cfg, clip_frames=clip_frames))

    logger = tracker.logger(parent)
    status = "FAILED"
    try:
        if is_new:
            logger.log_params(dataclasses.asdict(cfg) | {"checkpoint": str(checkpoint), "shards": str(shards)})
        if tasks:
            done |= _schedule(tasks, cfg, full_bytes, tracker)
        results = [done[p] for p in pairs]
        atomic_write_json(out_dir / "fleet_results.json", results)
        table = results_table(results)
        atomic_write_text(out_dir / "fleet_results.md", table + "\n")
        print(table, flush=True)
        logger.log_metrics(summary_metrics(results), record["launches"])
        logger.log_artifact(out_dir / "fleet_results.md")
        logger.log_artifact(out_dir / "fleet_results.json")
        for png in _charts(results, out_dir):
            logger.log_image(png, artifact_path="charts")
        status = "FINISHED"
    except KeyboardInterrupt:
        status = "KILLED"
        raise
    finally:
        logger.close(status)
    _say(f"results: {out_dir / 'fleet_results.md'}; {tracker.label}: {parent.ui_url}")
    return results
