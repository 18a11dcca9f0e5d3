"""``sray sweep``: training jobs on Ray Tune, one parent run and a child run per trial (docs/sweeps.md)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from sray.jobs.methods.flags import add_tracker_flags, refuse
from sray.platform.config.overrides import apply_settings
from sray.platform.config.recipes import RECIPES, get_recipe
from sray.platform.config.train_config import apply_override
from sray.platform.sweep.options import SpecFile, SweepRequest, load_spec_file, merge_options
from sray.platform.sweep.spec import check_unique, parse_assignment
from sray.platform.train.inputs import InputError

DEFAULT_OUT = "outputs/sweeps"
"""Folder holding sweeps unless ``--out`` says otherwise."""
OPTION_FLAGS = {"samples": (int, "draws of the random parameters (default 1)"),
                "seeds": (int, "seeds per point: run.seed=grid(0..N-1)"), "seed": (int, "seed of the parameter draws"),
                "metric": (str, "validation metric to compare by (default val/miou)"),
                "mode": (str, "max or min (default max)"), "scheduler": (str, "asha (default) or none"),
                "grace": (int, "ASHA: steps before a trial can be stopped (default run.ckpt_every)"),
                "reduction_factor": (float, "ASHA: 1 in this many trials continues at each rung (default 3)"),
                "max_concurrent": (int, "trials at once (default: as many as the cluster fits)"),
                "steps": (int, "budget per trial in steps (optim.steps)"),
                "cpu_seconds": (float, "budget per trial in CPU seconds summed over its ranks (optim.cpu_seconds)"),
                "minutes": (float, "budget per trial in wall-clock minutes")}
"""Flags of the sweep's options (``SweepOptions``; a spec file's keys of the same names): type and help."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray sweep``."""
    p = sub.add_parser("sweep", help="hyperparameter sweep of training jobs on Ray Tune (ASHA, resumable)")
    p.add_argument("spec", nargs="?", type=Path, help="YAML spec file (keys: recipe, data, set, params and the "
                                                     "options below)")
    p.add_argument("--param", dest="params", action="append", default=[], metavar="SECTION.FIELD=SPEC",
                   help="swept field: choice(a,b,..) uniform(lo,hi) loguniform(lo,hi) grid(a,b,..) (repeatable)")
    p.add_argument("--recipe", choices=sorted(RECIPES), help="starting config (default synth-small)")
    p.add_argument("--data", help="shard folder (data.shards)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="fixed override of every trial, as sray train --set (repeatable)")
    p.add_argument("--workers", type=int, help="Ray Train workers per trial (run.workers)")
    p.add_argument("--gpus-per-worker", type=float, help="GPUs per worker, fractions allowed with one worker")
    add_tracker_flags(p)
    for name, (kind, text) in OPTION_FLAGS.items():
        p.add_argument(f"--{name.replace('_', '-')}", dest=name, type=kind, help=text)
    p.add_argument("--name", help="sweep name (default sweep-<UTC time>)")
    p.add_argument("--out", type=Path, default=Path(DEFAULT_OUT), help=f"folder of sweeps (default {DEFAULT_OUT})")
    p.add_argument("--address", help="join this Ray cluster (default: start Ray locally in-process)")
    p.add_argument("--resume", metavar="NAME", help="continue the interrupted sweep NAME (its recorded spec)")
    p.set_defaults(func=_sweep)


def _name(out: Path) -> str:
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    name, n = f"sweep-{stamp}", 1
    while (out / name).exists():
        n += 1
        name = f"sweep-{stamp}-{n}"
    return name


def build_request(args: argparse.Namespace) -> SweepRequest:
    """The sweep the command line asks for: the spec file's values, overridden by the flags."""
    spec = load_spec_file(args.spec) if args.spec else SpecFile()
    options = merge_options(spec.options, {name: getattr(args, name) for name in OPTION_FLAGS})
    params = {p.path: p for p in spec.params} | {p.path: p for p in map(parse_assignment, args.params)}
    check_unique(list(params.values()))
    base = get_recipe(args.recipe or spec.recipe or "synth-small")
    flags = {"data.shards": args.data or spec.data, "run.workers": args.workers,
             "run.gpus_per_worker": args.gpus_per_worker, "run.tracker": args.tracker,
             "run.tracking_uri": args.tracking_uri}
    apply_settings(base, flags, [*spec.sets, *args.overrides], apply_override)
    return SweepRequest(name=args.name or _name(args.out), out=args.out, base=base, params=list(params.values()),
                        options=options)


def _sweep(args: argparse.Namespace) -> int:
    from sray.platform.train.resources import InfeasibleRequest

    refused = (FileExistsError, FileNotFoundError, ValueError, InputError, InfeasibleRequest)
    if args.resume and (args.spec or args.params or args.overrides or args.name):
        return refuse("sweep", f"--resume {args.resume} continues the recorded sweep; leave out the spec file, "
                       "--param, --set and --name")
    try:
        if args.resume:
            from sray.platform.sweep.driver import resume_sweep

            result = resume_sweep(args.out, args.resume, args.address)
        else:
            from sray.platform.sweep.driver import run_sweep

            result = run_sweep(build_request(args), args.address)  # every check runs before Ray starts
    except refused as e:
        return refuse("sweep", str(e).splitlines()[0] if str(e) else type(e).__name__)
    print((result.folder / "results.md").read_text(), flush=True)
    print(f"[sweep] results: {', '.join(str(f) for f in result.files)}\n"
          f"[sweep] parent run: {result.parent.ui_url}", flush=True)
    if not result.complete:
        print(f"[sweep] some trials are unfinished; continue with: sray sweep --resume {result.folder.name}"
              + (f" --out {args.out}" if str(args.out) != DEFAULT_OUT else ""), flush=True)
        return 1
    return 0
