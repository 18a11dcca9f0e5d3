"""Training cost of the variants of ``sray lab accuracy``: seconds per pretraining step, measured side by
side, and the chart of zero-shot mIoU against it (accuracy against training speed).

Each variant's step is the training step of its cells (the preset's recipe and overrides, the variant's
model settings: ``accuracy_cells.cell_config``) at the preset's batch and image size, on a synthetic
scene (``workloads``: the model alone, no data loading). Every variant runs in fresh processes, the
variants alternating round by round, so a load change on the machine hits all of them alike; the
median over the rounds is kept. The result is stored next to the cells (:data:`STEP_TIMES_FILE`) and
the tables read it from there.
"""

from __future__ import annotations

import dataclasses
import json
import statistics
import textwrap
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import torch
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png
from sray.jobs.bench.model_cost import run_in_fresh_process
from sray.jobs.bench.speed_accuracy import pareto
from sray.lab.accuracy.cells import cell_config
from sray.lab.accuracy.plan import Cell, Preset

STEP_TIMES_FILE = "step_times.json"
"""Stored step times of a benchmark folder: {"machine": ..., "variants": {variant: {...}}}."""
ROUNDS = 3
"""Fresh processes per variant, run alternately."""
TIMED_STEPS = 3
"""Steps timed in each process after its warm-up step (the process keeps their median)."""


def step_spec(variant: str, p: Preset, device: torch.device) -> dict[str, Any]:
    """The ``workloads`` spec of one pretraining step of ``variant`` in preset ``p``: its cells' model
    section whole, their implementation and rays per piece, rays per batch and precision, the preset's image
    size."""
    cfg = cell_config(Cell(variant, 0), p, Path("shards"), Path("out"), "")
    m = cfg.model
    return {"name": variant, "rays": cfg.data.rays_per_batch, "coarse": m.n_coarse, "fine": m.n_fine,
            "views": m.n_source, "hw": (p.world.height, p.world.width),
            "dtype": {"no": "fp32", "bf16": "bf16", "fp16": "fp16"}[cfg.run.precision],
            "model": dataclasses.asdict(m), "impl": cfg.runtime.impl, "piece": cfg.runtime.train_piece,
            "steps": TIMED_STEPS, "device": str(device)}


def _step_key(spec: dict[str, Any]) -> str:
    """What makes two variants' steps the same work: the spec without its name."""
    return json.dumps({k: x for k, x in spec.items() if k != "name"}, sort_keys=True, default=str)


def measure_step_times(p: Preset, variants: list[str], device: torch.device,
                       rounds: int = ROUNDS) -> dict[str, dict[str, Any]]:
    """Seconds per pretraining step of each variant, ``rounds`` fresh processes each, alternating.

    Variants whose steps are the same work (``long`` and ``full``: only the budget differs) are timed once.
    Returns variant -> {"s_per_step": median over the rounds, "runs": every round's seconds, "rays",
    "peak_rss_gib", "same_step_as": the variant that was timed}."""
    specs = {v: step_spec(v, p, device) for v in variants}
    first_of: dict[str, str] = {}  # a step's spec -> the first variant with it (long and full share one)
    same_as = {v: first_of.setdefault(_step_key(specs[v]), v) for v in variants}
    timed = [v for v in variants if same_as[v] == v]
    runs: dict[str, list[dict]] = {v: [] for v in timed}
    for _ in range(rounds):
        for v in timed:
            runs[v].append(run_in_fresh_process(specs[v]))
            print(f"[bench] step time {v}: {runs[v][-1]['seconds']:.3f} s", flush=True)
    return {v: {"s_per_step": statistics.median(r["seconds"] for r in runs[same_as[v]]),
                "runs": [r["seconds"] for r in runs[same_as[v]]], "rays": specs[v]["rays"],
                "peak_rss_gib": max(r["rss_bytes"] for r in runs[same_as[v]]) / 2**30,
                "same_step_as": same_as[v]} for v in variants}


def store_step_times(out: Path, times: dict[str, dict[str, Any]], machine: str) -> Path:
    """Write ``times`` (with the machine line) to ``out``/:data:`STEP_TIMES_FILE`, atomically."""
    path = Path(out) / STEP_TIMES_FILE
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps({"machine": machine, "variants": times}, indent=1) + "\n")
    tmp.replace(path)
    return path


def read_step_times(out: Path) -> dict[str, Any] | None:
    """The stored step times of a benchmark folder, or None when none were measured."""
    path = Path(out) / STEP_TIMES_FILE
    return json.loads(path.read_text()) if path.exists() else None


def step_cost_chart(scores: dict[str, list[float]], seconds: dict[str, float], steps: dict[str, int], path: Path,
                    title: str, caption: str) -> Path:
    """Zero-shot mIoU (%, mean with the seeds' min-max as error bars) against seconds per pretraining step.

    ``scores`` label -> per-seed mIoU %, ``seconds`` label -> s/step, ``steps`` label -> pretraining steps.
    The Pareto front joins the points trained for the most common number of steps (equal budgets); a
    point trained longer or shorter is drawn hollow, off the front."""
    labels = [k for k in scores if k in seconds]
    budget = Counter(steps[k] for k in labels).most_common(1)[0][0] if labels else 0
    points = {k: (seconds[k], float(np.mean(scores[k]))) for k in labels}
    fig = Figure(figsize=(8, 5.5))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for k in labels:
        x, y = points[k]
        lo, hi = y - min(scores[k]), max(scores[k]) - y
        equal = steps[k] == budget
        ax.errorbar([x], [y], yerr=[[lo], [hi]], fmt="o", capsize=3, color="tab:blue" if equal else "tab:gray",
                    mfc=None if equal else "white")
        ax.annotate(f"{k} ({len(scores[k])} seed{'s' if len(scores[k]) > 1 else ''}, {steps[k]} steps)", (x, y),
                    textcoords="offset points", xytext=(5, 4), fontsize=7)
    front = [r["name"] for r in pareto([{"name": k, "s": xy[0], "miou": xy[1]} for k, xy in points.items()
                                        if steps[k] == budget], cost="s")]
    ax.plot([points[k][0] for k in front], [points[k][1] for k in front], color="tab:orange", lw=1.5,
            label=f"Pareto front ({budget} steps each; mean over seeds)")
    ax.set_xlabel("seconds per pretraining step (measured side by side, this machine)")
    ax.set_ylabel("zero-shot mIoU (%): mean, bars = seed range")
    ax.set_title(title + "\n" + "\n".join(textwrap.wrap(caption, 115)), fontsize=7)
    ax.margins(x=0.25)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    return save_png(fig, path, dpi=120)
