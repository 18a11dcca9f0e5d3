"""A training sweep's trial: the job ``<sweep>-<key>`` with the point set via ``sray train``'s ``--set``, nested under
the sweep's run, reporting to Tune at each checkpoint; a relaunch resumes it, a stop request becomes its STOP file."""

from __future__ import annotations

import copy
import functools
import shutil
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ray.tune.integration.ray_train import TuneReportCallback

from sray.platform.config.train_config import CONFIG_FILE, TrainConfig, apply_override, load_job_config
from sray.platform.sweep.study import TrialContext
from sray.platform.sweep.spec import Param, SpecError
from sray.platform.tracking.tracker import RunHandle
from sray.platform.train.launcher import launch_training
from sray.platform.train.validation import GROUPS
from sray.platform.train.worker import STOP_FILE

TIME_ATTR = "step"
"""Key of a training job's reports that measures its progress (ASHA's time axis)."""
SCORE_NAMES = ("miou", "total_acc", "class_avg_acc", "miou_per_image", "psnr", "ssim")
"""Scores each validation group reports (``sray.platform.eval.view_scoring.score_views``)."""


def job_name(sweep: str, key: str) -> str:
    """The training job (and tracked run) of trial ``key``: ``<sweep>-<key>``."""
    return f"{sweep}-{key}"


def trial_config(base: TrainConfig, point: Mapping[str, Any], name: str = "") -> TrainConfig:
    """A copy of ``base`` with the point's values (job named ``name`` if given); :class:`SpecError` names a bad one."""
    cfg = copy.deepcopy(base)
    for path, value in point.items():
        try:
            apply_override(cfg, f"{path}={value!r}" if isinstance(value, float) else f"{path}={value}")
        except ValueError as e:
            raise SpecError(f"sweep parameter {path}: {e}") from None
    if name:
        cfg.run.name = name
    return cfg


def check_params(base: TrainConfig, params: list[Param]) -> None:
    """:class:`SpecError` unless each parameter's field exists and takes its values (range bounds; ranges: floats)."""
    for param in params:
        ranged = param.kind in ("uniform", "loguniform")
        hint = ("; uniform and loguniform draw floats: for an integer or text field list the values with choice(...) "
                "or grid(...)") if ranged else ""
        try:
            configs = [trial_config(base, {param.path: value}) for value in param.values]
        except SpecError as e:
            raise SpecError(f"{e}{hint}") from None
        if ranged and not all(isinstance(functools.reduce(getattr, param.path.split("."), c), float) for c in configs):
            raise SpecError(f"sweep parameter {param.path}: {param.spec} on a field that is not a float{hint}")


def check_metric(metric: str, configs: list[TrainConfig]) -> None:
    """The metric is a validation score every report of every trial carries (validation at each checkpoint)."""
    group, _, score = metric.partition("/")
    if group not in GROUPS or score not in SCORE_NAMES:
        raise SpecError(f"--metric {metric!r}: a training trial reports {', '.join(f'{g}/<score>' for g in GROUPS)} "
                        f"with <score> one of {', '.join(SCORE_NAMES)}, e.g. val/miou")
    for cfg in configs:
        if cfg.run.ckpt_every % cfg.run.val_every:
            raise SpecError(f"run.val_every {cfg.run.val_every}: a trial reports to the sweep at each checkpoint "
                            f"(run.ckpt_every {cfg.run.ckpt_every}) and only a validation gives {metric}; set "
                            f"run.val_every to a divisor of run.ckpt_every, e.g. {cfg.run.ckpt_every}")


def _forward_stop(ctx: TrialContext, stop_file: Path, done: threading.Event) -> None:
    """Turn the trial's stop request into the job's STOP file (the workers checkpoint and end)."""
    while not done.wait(0.5):
        if ctx.stop_requested() and stop_file.parent.is_dir():
            stop_file.touch()
            return


def run_training_trial(point: dict[str, Any], ctx: TrialContext, base: dict[str, Any], sweep: str,
                       parent: RunHandle) -> None:
    """The point function of a training sweep: train ``base`` (a config dict) with ``point`` set, under ``parent``."""
    cfg = trial_config(TrainConfig.from_dict(base), point, job_name(sweep, ctx.key))
    job_dir = cfg.job_dir()
    resume = (job_dir / CONFIG_FILE).is_file()
    if resume:
        cfg = load_job_config(cfg.run.output_dir, cfg.run.name)
    elif job_dir.exists():
        shutil.rmtree(job_dir)  # a launch that died before writing its config left nothing to resume
    done = threading.Event()
    watcher = threading.Thread(target=_forward_stop, args=(ctx, job_dir / STOP_FILE, done), daemon=True)
    watcher.start()
    try:
        launch_training(cfg, resume=resume, parent=parent, callbacks=[TuneReportCallback()])
    finally:
        done.set()
