"""``sray submit``: send a ``sray train`` job to a Ray cluster's Jobs API; ``--wait`` follows it. Paths are made
absolute here (the driver starts in another folder) and must be on storage the nodes share."""

from __future__ import annotations

import argparse
import shlex
import time
from pathlib import Path

from sray.jobs.methods.flags import refuse
from sray.jobs.train_cmd import add_train_flags, build_config
from sray.platform.common.fault_hook import propagated_env

FORWARDED = {"recipe": "--recipe", "workers": "--workers", "gpus_per_worker": "--gpus-per-worker",
             "precision": "--precision", "tracker": "--tracker", "tracking_uri": "--tracking-uri"}
"""Flags passed on to ``sray train`` as given."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray submit``."""
    p = sub.add_parser("submit", help="send a `sray train` job to a Ray cluster (Ray Jobs API)",
                       description="Submit a training job to the head of a Ray cluster; it trains on the worker "
                                   "nodes. With --wait, stream its log and exit with its status (0 succeeded, "
                                   "1 failed, 3 stopped).")
    add_train_flags(p)
    p.add_argument("--address", required=True, help="the head's Jobs API, e.g. http://127.0.0.1:8265 "
                                                    "(`sray cluster status` prints it)")
    p.add_argument("--working-dir", help="folder shipped to the cluster with the job (default: none; sray is "
                                         "installed on the nodes)")
    p.add_argument("--wait", action="store_true", help="follow the job to its end, streaming its log")
    p.set_defaults(func=run)


def train_command(args: argparse.Namespace, name: str, output_dir: Path, data: Path | None) -> list[str]:
    """The ``sray train`` command line the job runs on the head (absolute paths, a fixed job name)."""
    argv = ["sray", "train", "--address", "auto"]
    argv += ["--resume", name] if args.resume else ["--name", name]
    for field, flag in FORWARDED.items():
        value = getattr(args, field)
        if value is not None and not (args.resume and field == "recipe"):
            argv += [flag, str(value)]
    if data is not None:
        argv += ["--data", str(data)]
    for assignment in [*args.overrides, f"run.output_dir={output_dir}"]:
        argv += ["--set", assignment]
    return argv


def job_runtime_env(working_dir: str | None) -> dict[str, object] | None:
    """The job's Ray runtime env: the shipped folder, and ``SRAY_FAULTS`` when set here (a drill's faults)."""
    env: dict[str, object] = {"working_dir": str(Path(working_dir).resolve())} if working_dir else {}
    if propagated_env():
        env["env_vars"] = propagated_env()
    return env or None


def run(args: argparse.Namespace) -> int:
    """Check the request here, submit it, and with ``--wait`` follow it; exit 2 for a bad request."""
    from sray.platform.train.inputs import InputError, check_train_inputs

    try:
        cfg = build_config(args)  # refuse bad flags here, not minutes later on the cluster
        check_train_inputs(cfg, resume=bool(args.resume))
    except (InputError, FileNotFoundError, FileExistsError, ValueError) as e:
        return refuse("submit", e)
    from sray.platform.cluster import job_client

    name = args.resume or cfg.run.name or f"{cfg.recipe}-{time.strftime('%Y%m%d-%H%M%S', time.gmtime())}"
    data = Path(args.data).resolve() if args.data else None
    argv = train_command(args, name, Path(cfg.run.output_dir).resolve(), data)
    entrypoint = " ".join(shlex.quote(a) for a in argv)
    runtime_env = job_runtime_env(args.working_dir)
    try:
        job_id = job_client.submit(args.address, entrypoint, runtime_env=runtime_env)
    except Exception as e:  # noqa: BLE001 - the head is unreachable or refused us: one line, the fix
        reason = str(e).strip().splitlines()[-1][:300] if str(e).strip() else type(e).__name__
        return refuse("submit", f"the Jobs API at {args.address} refused the job ({reason}); check --address "
                      "(`sray cluster status`) and the Ray token (RAY_AUTH_MODE=token, RAY_AUTH_TOKEN_PATH)")
    print(f"[sray] submitted {job_id}: job {name}\n[sray] {entrypoint}\n[sray] follow: ray job logs --follow {job_id} "
          f"--address {args.address}\n[sray] stop:   ray job stop {job_id} --address {args.address}\n[sray] resume: "
          f"sray submit --resume {name} --set run.output_dir={Path(cfg.run.output_dir).resolve()} --address "
          f"{args.address}", flush=True)
    if not args.wait:
        return 0
    try:
        status = job_client.follow(args.address, job_id)
    except KeyboardInterrupt:
        print(f"\n[sray] stopped following; the job goes on (ray job stop {job_id} --address {args.address})")
        return 130
    print(f"[sray] job {job_id} {status}", flush=True)
    return job_client.EXIT_CODES.get(status, 1)
