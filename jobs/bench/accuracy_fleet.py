"""The fleet comparison of ``sray bench accuracy``: every registered per-scene method whose requirements the
benchmark's settings meet finetunes every unseen scene from the headline model under one equal wall-clock budget.

The methods come from the method registry, in its order: a method is compared when its record's
``checked_config`` accepts the benchmark's fleet config (a record without one always is); a method whose check
raises ValueError (a requirement not given: ``2d-transfer`` without ``--segmenter``) is left out and named (and
with it S-Ray given the source depth, which stands only beside a method that reads depth), while a
FileNotFoundError (a given file missing) stops the benchmark before any cell runs. The fleet's folder holds
``done.json`` once it finished, naming its checkpoint and methods; a later run with more methods (a segmenter given)
runs the missing (scene, method) pairs only; one that finetuned from another checkpoint is refused (move it away).
A ``done.json`` written before it named its methods counts the methods of the results stored beside it.
"""

from __future__ import annotations

import json
from pathlib import Path

from sray.data_tools.atomic import atomic_write_json
from sray.jobs.bench.accuracy_plan import EXPERIMENT, Preset
from sray.platform.config.fleet_config import FleetConfig
from sray.platform.finetune.fleet import run_fleet
from sray.platform.finetune.methods.registry import METHODS, with_depth_twins
from sray.platform.viz.charts import write_fleet_charts
from sray.platform.viz.curves import read_fleet_results

DONE_FILE = "done.json"
"""File in the fleet's folder marking it finished: ``{"checkpoint": ..., "methods": [...]}``."""


def fleet_config(p: Preset, segmenter: Path | None = None) -> FleetConfig:
    """The comparison's fleet config: the preset's budget, equal for every method, with no early stop; its held-out
    sources and stride; ``segmenter`` as ``transfer.segmenter`` (empty without one)."""
    cfg = FleetConfig()
    cfg.finetune.max_seconds = p.budget_s
    cfg.finetune.max_steps = 100_000
    cfg.finetune.patience = 10_000  # equal budgets: no early stop in the comparison
    cfg.finetune.held_out.n_source = p.eval_sources
    cfg.finetune.held_out.stride = p.fleet_eval_stride
    cfg.gpus_per_task = p.fleet_gpus_per_task
    cfg.experiment = EXPERIMENT
    cfg.transfer.segmenter = str(segmenter) if segmenter is not None else ""
    return cfg


def compared_methods(cfg: FleetConfig) -> tuple[FleetConfig, list[str], dict[str, str]]:
    """``cfg`` as the methods' checks return it, the registered methods it meets the requirements of (registry
    order, a depth twin beside the methods that read depth: ``with_depth_twins``) and the others with the reason
    each was left out (its check's message)."""
    compared, left_out = [], {}
    for name, method in METHODS.items():
        if method.given_depth_of:
            continue
        if method.checked_config is None:
            compared.append(name)
            continue
        try:
            cfg = method.checked_config(cfg)
        except ValueError as e:
            left_out[name] = str(e)
            continue
        compared.append(name)
    return cfg, with_depth_twins(compared), left_out


def methods_done(fleet_dir: Path) -> set[str] | None:
    """The methods of the finished fleet in ``fleet_dir``: its ``done.json``'s ``methods``, or for one written before
    it named them, the methods of the results stored there; None when no fleet finished there."""
    done = Path(fleet_dir) / DONE_FILE
    if not done.exists():
        return None
    record = json.loads(done.read_text())
    if "methods" in record:
        return set(record["methods"])
    return {r["method"] for r in read_fleet_results(fleet_dir)}


def fleet_checkpoint(fleet_dir: Path) -> str | None:
    """The checkpoint the finished fleet in ``fleet_dir`` finetuned from (its ``done.json``); None when none finished
    there."""
    done = Path(fleet_dir) / DONE_FILE
    return json.loads(done.read_text())["checkpoint"] if done.exists() else None


def run_comparison(cfg: FleetConfig, methods: list[str], checkpoint: Path, shards: Path, scenes: list[str],
                   fleet_dir: Path, tracking_uri: str) -> bool:
    """Finetune every scene with each of ``methods`` (pairs already finished are skipped), chart the results and
    mark the fleet done with every method it holds; nothing when a finished fleet holds them all already; ValueError
    when the finished fleet there finetuned from another checkpoint. Returns whether a fleet ran."""
    source = fleet_checkpoint(fleet_dir)
    if source is not None and Path(source) != Path(checkpoint):
        raise ValueError(f"{Path(fleet_dir) / DONE_FILE}: checkpoint: this fleet finetuned from {source}, not from "
                         f"{checkpoint}; move {fleet_dir} away to finetune from the new model (its results are kept)")
    done = methods_done(fleet_dir)
    if done is not None and set(methods) <= done:
        return False
    results = run_fleet(cfg, checkpoint, shards, scenes, fleet_dir, tracking_uri, methods)
    write_fleet_charts(results, fleet_dir / "charts", METHODS)
    held = [m for m in METHODS if m in {*methods, *(done or ())}]
    atomic_write_json(fleet_dir / DONE_FILE, {"checkpoint": str(checkpoint), "methods": held})
    return True
