"""``sray train``: run a training job here or, with ``--address``, on a Ray cluster."""

from __future__ import annotations

import argparse

from sray.jobs.methods.flags import add_tracker_flags, refuse
from sray.platform.config.overrides import apply_settings
from sray.platform.config.recipes import RECIPES, get_recipe
from sray.platform.config.train_config import TrainConfig, apply_override, load_job_config


def add_train_flags(p: argparse.ArgumentParser) -> None:
    """The flags ``sray train`` and ``sray submit`` share."""
    p.add_argument("--recipe", default="synth-small", choices=sorted(RECIPES), help="starting config")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="override any config field, e.g. --set optim.steps=2000 (repeatable)")
    p.add_argument("--data", help="shard folder (data.shards)")
    p.add_argument("--workers", type=int, help="Ray Train workers (run.workers)")
    p.add_argument("--gpus-per-worker", type=float, help="GPUs per worker, fractions allowed")
    p.add_argument("--precision", choices=["no", "bf16", "fp16"], help="mixed precision (fp16: CUDA only)")
    add_tracker_flags(p)
    p.add_argument("--name", help="job name (unique; default <recipe>-<timestamp>)")
    p.add_argument("--resume", metavar="NAME", help="continue the stopped or crashed job NAME")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray train``."""
    train = sub.add_parser("train", help="train S-Ray with Ray Train + Accelerate, tracked in MLflow")
    add_train_flags(train)
    train.add_argument("--address", help="join this Ray cluster (default: start Ray locally in-process)")
    train.set_defaults(func=_train)


def build_config(args: argparse.Namespace) -> TrainConfig:
    """The job's TrainConfig: the recipe (or a resumed job's saved config) plus flags and --set."""
    cfg = get_recipe(args.recipe)
    if args.resume:
        # the job's folder is under the output folder the user names (--set run.output_dir=...), else the recipe's
        named = [a.split("=", 1)[1] for a in args.overrides if a.split("=", 1)[0].strip() == "run.output_dir"]
        cfg = load_job_config(named[-1] if named else cfg.run.output_dir, args.resume)
        cfg.run.name = args.resume
    flags = {"data.shards": args.data, "run.workers": args.workers, "run.gpus_per_worker": args.gpus_per_worker,
             "run.precision": args.precision, "run.tracker": args.tracker, "run.tracking_uri": args.tracking_uri,
             "run.name": None if args.resume else args.name}
    apply_settings(cfg, flags, args.overrides, apply_override)
    return cfg


def _train(args: argparse.Namespace) -> int:
    from sray.platform.train.inputs import check_train_inputs

    try:  # inputs are checked before torch and Ray are even imported: a bad one fails in seconds
        cfg = build_config(args)
        check_train_inputs(cfg, resume=bool(args.resume), address=args.address)
    except (FileExistsError, FileNotFoundError, ValueError) as e:
        return refuse("train", e)
    from sray.platform.train.launcher import launch_training
    from sray.platform.train.resources import InfeasibleRequest

    try:
        outcome = launch_training(cfg, address=args.address, resume=bool(args.resume))
    except (InfeasibleRequest, FileExistsError, FileNotFoundError, ValueError) as e:
        return refuse("train", e)
    return 0 if outcome.status in ("FINISHED", "KILLED") else 1

