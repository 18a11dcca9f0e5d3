"""``sray gpu-check``: the ``stage_*`` functions (``CheckContext -> StageResult``) in order, the report saved after
each so a run resumes (a raising stage is recorded failed); on a GPU it is docs/benchmarks.md's "GPU check" section."""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from pathlib import Path

import torch

from sray.platform.common.bench_doc import Bench, record

from . import stage_bench, stage_env, stage_fleet, stage_minutes, stage_precision, stage_ray, stage_training
from .context import CheckContext
from .report import STAGE_NAMES, StageResult, load_report, markdown, save_report

STAGES: dict[str, Callable[[CheckContext], StageResult]] = dict(zip(STAGE_NAMES, (
    stage_env.environment, stage_env.tests, stage_precision.run, stage_training.run, stage_training.recipe,
    stage_bench.run, stage_bench.profile, stage_ray.run, stage_fleet.run, stage_minutes.run), strict=True))
"""Every stage, in the order they run (each at most a few minutes on a GPU)."""


class NoCudaDevice(RuntimeError):
    """``sray gpu-check`` without --dry-run on a machine where torch sees no CUDA device."""


def _run_stage(name: str, ctx: CheckContext) -> StageResult:
    start = time.perf_counter()
    try:
        result = STAGES[name](ctx)
    except Exception as err:  # a failing stage is a result; the next stage still runs
        (ctx.out / f"{name}.error.log").write_text(traceback.format_exc())
        result = StageResult("failed", f"{type(err).__name__}: {err}"[:300])
    result.seconds = time.perf_counter() - start
    return result


def run_gpu_check(stages: list[str], out: Path, dry_run: bool, fresh: bool, repo: Path, doc: Path | None) -> dict:
    """Run the chosen stages not yet in the report, printing a line per stage; returns the report."""
    unknown = [s for s in stages if s not in STAGES]
    if unknown:
        raise ValueError(f"unknown stage(s) {unknown}; choose from {list(STAGES)}")
    if not dry_run and not torch.cuda.is_available():
        raise NoCudaDevice(f"no CUDA device is visible to torch {torch.__version__}; run sray gpu-check on a GPU "
                           "machine, or add --dry-run to check the command itself on the CPU")
    ctx = CheckContext(torch.device("cpu" if dry_run else "cuda"), dry_run, out.resolve(), repo.resolve())
    ctx.out.mkdir(parents=True, exist_ok=True)
    report = {"device": None, "stages": {}} if fresh else load_report(ctx.out)
    report["device"] = torch.cuda.get_device_name(0) if ctx.device.type == "cuda" else "CPU (dry run)"
    for i, name in enumerate(stages, 1):
        if name in report["stages"]:
            print(f"[gpu-check {i}/{len(stages)}] {name}: already in the report "
                  f"({report['stages'][name].status}), skipped", flush=True)
            continue
        print(f"[gpu-check {i}/{len(stages)}] {name} ...", flush=True)
        result = report["stages"][name] = _run_stage(name, ctx)
        save_report(ctx.out, report)
        print(f"[gpu-check {i}/{len(stages)}] {name}: {result.status} in {result.seconds:.0f} s: {result.summary}",
              flush=True)
    text = markdown(report, list(STAGES))
    (ctx.out / "gpu_check.md").write_text(text + "\n")
    if doc is not None and not dry_run:
        record(Bench("gpu-check", "GPU check"), "Stages", text, doc)
    return report
