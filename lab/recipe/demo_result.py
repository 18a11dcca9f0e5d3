"""``sray lab demo-result OUT``: a finished ``sray demo --out OUT`` read from its own output files into a stored result
of study ``demo`` (``jobs/studies/results/demo/make-demo--s<seed>.json``, the format of ``sray.lab.studies.results``),
which the README's ``synth-demo`` recipe card and the demo's time are published from.

What it reads under OUT (``sray.jobs.demo`` writes them):

* ``eval/metrics.json``: the zero-shot evaluation, its protocol and the checkpoint it scored;
* that checkpoint's training job, ``train/<job>/``: its last checkpoint's counters (wall and CPU seconds, peak memory),
  step, recipe, 2D warm-up steps and seed (the folder must hold that one job: a fresh demo folder);
* ``fleet/fleet.json`` and ``fleet/fleet_results.json``: per method the held-out mIoU after its finetune, each finished
  room checked against the fleet's time budget (``--finetune-seconds``, the demo's flag of that name);
* ``render/frames.json``: the fly-through's render rate;
* the modification times of every file under OUT: the demo's wall time, from its first output file to its last.

The machine is this one (``describe_machine``) and the commit the checkout the command runs in: run it where the demo
ran, right after it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from sray.data_tools.shards.manifest import read_manifest
from sray.lab.recipe.results import ResultError, number, train_state
from sray.lab.studies.fleet_ceilings import fleet_blocks
from sray.lab.studies.results import FORMAT, write_result
from sray.lab.studies.trial import current_commit, split_metrics
from sray.platform.common.machine import describe_machine
from sray.platform.render.flythrough import FRAMES_FILE

STUDY, ARM = "demo", "make-demo"
"""The study and arm a demo run is stored under."""
RESULTS_DIR = Path("jobs/studies/results") / STUDY
"""Where the demo's runs are stored, relative to the repository."""


def _json(path: Path) -> Any:
    """The JSON in ``path``; ResultError naming it when it is absent or unreadable."""
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ResultError(f"{path}: no such file; give the --out folder of a `sray demo` run that reached its "
                          "end") from None
    except (OSError, ValueError) as e:
        raise ResultError(f"{path}: not readable as JSON ({e})") from None


def training_job(out: Path, checkpoint: str) -> Path:
    """The demo's training job: ``OUT/train/<job>`` of the evaluated ``checkpoint`` (``.../<job>/checkpoints/
    step_*``); ResultError when ``OUT/train`` holds another job beside it (not one demo run's folder)."""
    job = Path(out) / "train" / Path(checkpoint).parent.parent.name
    if not job.is_dir():
        raise ResultError(f"{job}: no such training job, yet the evaluation scored {checkpoint}; give the --out "
                          "folder the demo ran in")
    others = sorted(p.name for p in job.parent.iterdir() if p.is_dir() and p != job)
    if others:
        raise ResultError(f"{job.parent}: holds jobs {others} beside {job.name}; read the folder of one demo run "
                          "(sray demo --out NEW_FOLDER)")
    return job


def check_budget(result: dict[str, Any], seconds: float, where: Path) -> None:
    """ResultError unless the finished fleet ``result`` ran with a ``seconds`` wall budget: every held-out point but
    the last within it, the last past it exactly when the budget stopped the finetune."""
    walls = [point["wall_s"] for point in result["curve"]]
    by_time = result["stop_reason"] == "max_seconds"
    if any(w >= seconds for w in walls[:-1]) or (walls[-1] >= seconds) != by_time:
        raise ResultError(f"{where}: {result['scene']}/{result['method']} trained {walls[-1]:.1f} s and stopped by "
                          f"{result['stop_reason']}, not a {seconds:g} s budget; pass the demo's --finetune-seconds")


def fleet_metrics(fleet: Path, checkpoint: str, seconds: float) -> dict[str, dict[str, Any]]:
    """Per method of the demo's fleet (folder ``fleet``), ``fleet_blocks``' fields and its budget; ResultError when the
    fleet finetuned another checkpoint, a room failed, or it ran with another budget than ``seconds``."""
    record = _json(fleet / "fleet.json")
    ran = Path(record.get("checkpoint", ""))
    if (ran.parent.parent.name, ran.name) != (Path(checkpoint).parent.parent.name, Path(checkpoint).name):
        raise ResultError(f"{fleet / 'fleet.json'}: checkpoint {ran}, the evaluation scored {checkpoint}; read the "
                          "folder of one demo run")
    results = _json(fleet / "fleet_results.json")
    for result in results:
        if result["status"] != "finished":
            raise ResultError(f"{fleet / 'fleet_results.json'}: {result['scene']}/{result['method']} "
                              f"{result['status']} ({result['error']}); rerun the demo")
        check_budget(result, seconds, fleet / "fleet_results.json")
    return {m: block | {"budget": f"{seconds:g} s per room"} for m, block in fleet_blocks(results).items()}


def render_metrics(frames: Path) -> dict[str, Any]:
    """The fly-through's wall seconds per frame (rendering and writing it), frames, size and render protocol."""
    record = _json(frames)
    rate = number(record, "frames_per_s", frames)
    return {"seconds_per_frame": round(1 / rate, 3), "frames": record["n_frames"],
            "size": f"{record['size']['width']}x{record['size']['height']}", "protocol": record["protocol_line"]}


def demo_metrics(out: Path, shards: Path) -> dict[str, Any]:
    """The demo's wall time (its output files' first to last modification, seconds) and its world's rooms."""
    times = [p.stat().st_mtime for p in Path(out).rglob("*") if p.is_file()]
    roles = [scene.meta.get("role") for scene in read_manifest(shards).scenes.values()]
    return {"wall_seconds": round(max(times) - min(times), 1), "wall_rule": "first to last output file",
            "train_rooms": roles.count("train"), "test_rooms": roles.count("test")}


def demo_result(out: Path, finetune_seconds: float = 60.0) -> dict[str, Any]:
    """The stored result of the demo run in folder ``out`` (module doc); ResultError naming the file and the fix."""
    out = Path(out)
    report = _json(out / "eval" / "metrics.json")
    job = training_job(out, report["checkpoint"])
    state, state_file = train_state(job)
    cfg, steps = state["config"], int(number(state, "step", state_file))  # the steps the job ran
    counters = {k: number(state, f"counters.{k}", state_file)
                for k in ("cpu_seconds", "wall_seconds", "peak_memory_mb")}
    shards, scenes, optim = Path(report["shards"]), list(report["scenes"]), cfg["optim"]
    warmup = int(optim["warmup_2d_steps"])
    return {"format": FORMAT, "study": STUDY, "arm": ARM, "seed": int(cfg["run"]["seed"]), "recipe": cfg["recipe"],
            "overrides": {}, "budget": {"cpu_seconds": optim["cpu_seconds"] or None, "steps": optim["steps"]},
            "trained": {"ray_steps": steps - warmup, "steps_2d": warmup,
                        "cpu_seconds": round(counters["cpu_seconds"], 1),
                        "wall_seconds": round(counters["wall_seconds"], 1),
                        "peak_memory_gib": round(counters["peak_memory_mb"] / 1024, 3)},
            "metrics": {"zero_shot": split_metrics(report, shards, scenes),
                        "fleet": fleet_metrics(out / "fleet", report["checkpoint"], finetune_seconds),
                        "render": render_metrics(out / "render" / FRAMES_FILE), "demo": demo_metrics(out, shards)},
            "machine": describe_machine(), "commit": current_commit(Path.cwd()),
            "source": f"run: sray demo --out {out}, read by `sray lab demo-result`"}


def write_demo_result(out: Path, results_dir: Path = RESULTS_DIR, finetune_seconds: float = 60.0) -> Path:
    """Read the demo run in ``out`` and store it under ``results_dir`` (replacing its seed's file); the file."""
    return write_result(results_dir, demo_result(out, finetune_seconds))
