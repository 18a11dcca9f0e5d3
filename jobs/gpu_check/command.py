"""``sray gpu-check``: sray's CUDA path by stages (torch and accelerate suffice; Ray, MLflow, webdataset ones skip)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sray.jobs.gpu_check.report import STAGE_NAMES


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray gpu-check``."""
    p = sub.add_parser("gpu-check", help="check the CUDA path stage by stage; report into docs/benchmarks.md")
    p.add_argument("--stages", nargs="+", default=list(STAGE_NAMES), choices=list(STAGE_NAMES),
                   metavar="STAGE", help=f"stages to run, in order (default: all of {', '.join(STAGE_NAMES)})")
    p.add_argument("--out", type=Path, default=Path("outputs/gpu-check"), help="report and scratch folder")
    p.add_argument("--dry-run", action="store_true", help="every stage on the CPU at toy size (tests the command)")
    p.add_argument("--fresh", action="store_true", help="ignore stages already in the report and run them again")
    p.add_argument("--doc", type=Path, default=None,
                   help="where a GPU run writes its section (default: docs/benchmarks.md of the checkout sray is "
                        "installed from; dry runs write only under --out)")
    p.set_defaults(func=_gpu_check)


def _gpu_check(args: argparse.Namespace) -> int:
    from sray.jobs.gpu_check.context import NotACheckout, checkout_root
    from sray.jobs.gpu_check.runner import NoCudaDevice, run_gpu_check

    try:
        repo = checkout_root()
        report = run_gpu_check(args.stages, args.out, args.dry_run, args.fresh, repo,
                               args.doc or repo / "docs" / "benchmarks.md")
    except (NotACheckout, NoCudaDevice) as err:
        print(f"sray gpu-check: {err}")
        return 2
    failed = [n for n, r in report["stages"].items() if r.status == "failed"]
    print(f"sray gpu-check: report in {args.out / 'gpu_check.md'}"
          + (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0
