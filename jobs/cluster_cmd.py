"""``sray cluster up|status|down|restart``: a local multi-node cluster (PostgreSQL, MLflow server, Ray head
and worker nodes) as processes on this machine, bound to 127.0.0.1 (docs/cluster.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sray.jobs.methods.flags import refuse

DEFAULT_DIR = Path("outputs/cluster")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray cluster``."""
    p = sub.add_parser("cluster", help="a local cluster: PostgreSQL + MLflow server + Ray head and worker nodes",
                       description="Start, show or stop a cluster of real processes on this machine (loopback "
                                   "only). `down` keeps the data; the next `up` finds the same runs.")
    p.add_argument("action", choices=["up", "status", "down", "restart"],
                   help="restart: stop one part (--part) and start it again, e.g. after it died")
    p.add_argument("--dir", type=Path, default=DEFAULT_DIR, help=f"cluster folder (default {DEFAULT_DIR})")
    p.add_argument("--workers", type=int, default=2, help="Ray worker nodes (default 2)")
    p.add_argument("--cpus-per-worker", type=int, default=1, help="logical CPUs per worker node (default 1)")
    p.add_argument("--part", help="for restart: postgres, mlflow, ray-head or ray-worker-<i>")
    p.add_argument("--outage", type=float, default=0.0, help="for restart: seconds the part stays down (drills)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the action; exit 2 with one line when the cluster cannot be started or found."""
    from sray.platform.cluster import local_cluster
    from sray.platform.cluster.processes import ClusterError

    try:
        if args.action == "up":
            print(f"[cluster] starting in {args.dir.resolve()} ...", flush=True)
            state = local_cluster.up(args.dir, workers=args.workers, cpus_per_worker=args.cpus_per_worker)
            took = ", ".join(f"{k} {v:g} s" for k, v in state.startup_s.items())
            print(f"[cluster] up: {took}\n{local_cluster.describe(state)}", flush=True)
        elif args.action == "status":
            print(local_cluster.describe(local_cluster.status(args.dir)))
        elif args.action == "restart":
            if not args.part:
                raise ClusterError("restart needs --part (postgres, mlflow, ray-head or ray-worker-<i>)")
            state = local_cluster.restart(args.dir, args.part, outage_s=args.outage)
            print(f"[cluster] restarted {args.part} in {state.startup_s[args.part]:g} s\n"
                  f"{local_cluster.describe(state)}")
        else:
            stopped = local_cluster.down(args.dir)
            print(f"[cluster] stopped {', '.join(stopped) if stopped else 'nothing (nothing was running)'}; "
                  f"data kept in {args.dir.resolve()}")
    except ClusterError as e:
        return refuse(f"cluster {args.action}", e)
    return 0
