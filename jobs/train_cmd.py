"""``sray train`` (run a training job here or on a cluster) and ``sray submit`` (Ray Jobs API)."""

from __future__ import annotations

import argparse
import shlex
import sys

from sray.jobs.recipes import RECIPES


def add_train_flags(p: argparse.ArgumentParser) -> None:
    """The flags ``sray train`` and ``sray submit`` share."""
    p.add_argument("--recipe", default="synth-small", choices=sorted(RECIPES), help="starting config")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="override any config field, e.g. --set optim.steps=2000 (repeatable)")
    p.add_argument("--data", help="shard folder (data.shards)")
    p.add_argument("--workers", type=int, help="Ray Train workers (run.workers)")
    p.add_argument("--gpus-per-worker", type=float, help="GPUs per worker, fractions allowed")
    p.add_argument("--precision", choices=["no", "bf16", "fp16"], help="mixed precision (fp16: CUDA only)")
    p.add_argument("--tracker", help="tracker to log to, by registry name (run.tracker; default: mlflow)")
    p.add_argument("--tracking-uri", help="the tracker's store, for MLflow its tracking URI (default: SQLite store "
                                          "in this folder)")
    p.add_argument("--name", help="job name (unique; default <recipe>-<timestamp>)")
    p.add_argument("--resume", metavar="NAME", help="continue the stopped or crashed job NAME")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray train`` and ``sray submit``."""
    train = sub.add_parser("train", help="train S-Ray with Ray Train + Accelerate, tracked in MLflow")
    add_train_flags(train)
    train.add_argument("--address", help="join this Ray cluster (default: start Ray locally in-process)")
    train.set_defaults(func=_train)

    submit = sub.add_parser("submit", help="send a `sray train` job to a Ray cluster (Ray Jobs API)")
    add_train_flags(submit)
    submit.add_argument("--address", required=True, help="Ray dashboard address, e.g. http://head:8265")
    submit.add_argument("--working-dir", default=".", help="folder shipped to the cluster (default: .)")
    submit.set_defaults(func=_submit)


def build_config(args: argparse.Namespace):
    """The job's TrainConfig: the recipe (or a resumed job's saved config) plus flags and --set."""
    from sray.jobs.recipes import get_recipe
    from sray.platform.config.overrides import apply_settings
    from sray.platform.config.train_config import apply_override
    from sray.platform.train.launcher import load_job_config

    cfg = get_recipe(args.recipe)
    if args.resume:
        cfg = load_job_config(cfg.run.output_dir, args.resume)
        cfg.run.name = args.resume
    flags = {"data.shards": args.data, "run.workers": args.workers, "run.gpus_per_worker": args.gpus_per_worker,
             "run.precision": args.precision, "run.tracker": args.tracker, "run.tracking_uri": args.tracking_uri,
             "run.name": None if args.resume else args.name}
    apply_settings(cfg, flags, args.overrides, apply_override)
    return cfg


def _train(args: argparse.Namespace) -> int:
    from sray.platform.train.launcher import launch_training
    from sray.platform.train.resources import InfeasibleRequest

    cfg = build_config(args)
    try:
        outcome = launch_training(cfg, address=args.address, resume=bool(args.resume))
    except (InfeasibleRequest, FileExistsError, FileNotFoundError, ValueError) as e:
        print(f"sray train: {e}", file=sys.stderr)
        return 2
    return 0 if outcome.status in ("FINISHED", "KILLED") else 1


def _submit(args: argparse.Namespace) -> int:
    from ray.job_submission import JobSubmissionClient

    build_config(args)  # refuse bad flags here, not minutes later on the cluster
    forwarded = [a for a in sys.argv[sys.argv.index("submit") + 1:]]
    drop = {"--address", "--working-dir"}
    entry, skip = [], False
    for a in forwarded:
        if skip:
            skip = False
            continue
        if a in drop:
            skip = True
            continue
        if a.split("=", 1)[0] in drop:
            continue
        entry.append(a)
    entrypoint = "sray train --address auto " + " ".join(shlex.quote(a) for a in entry)
    client = JobSubmissionClient(args.address)
    job_id = client.submit_job(entrypoint=entrypoint, runtime_env={"working_dir": args.working_dir})
    print(f"submitted {job_id}: {entrypoint}\n"
          f"follow:  ray job logs --follow {job_id} --address {args.address}\n"
          f"status:  ray job status {job_id} --address {args.address}\n"
          f"stop:    ray job stop {job_id} --address {args.address}")
    return 0
