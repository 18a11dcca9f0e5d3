"""``sray lab accuracy``: zero-shot mIoU with seeds over resumable cells, the attention ablation, the registered
per-scene methods at equal finetune budgets (docs/benchmarks.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(kinds: argparse._SubParsersAction) -> None:
    """Add ``accuracy`` to ``sray lab``'s commands."""
    accuracy = kinds.add_parser("accuracy", help="zero-shot mIoU with seeds (resumable cells), the attention "
                                "ablation, the registered per-scene methods at equal finetune budgets")
    accuracy.add_argument("--preset", choices=["cpu-small", "gpu"], default="cpu-small",
                          help="cpu-small: 2 CPU cores, over several runs of about an hour; gpu: for a GPU machine")
    accuracy.add_argument("--cells", nargs="+", default=None, metavar="VARIANT:SEED",
                          help="run only these cells of the preset's plan, e.g. long:0 full:1 (default: every "
                               "missing one)")
    accuracy.add_argument("--max-minutes", type=float, default=None,
                          help="start no new cell after this many minutes (the tables are written either way)")
    accuracy.add_argument("--no-fleet", action="store_true", help="skip the finetune comparison")
    accuracy.add_argument("--segmenter", type=Path, default=None,
                          help="2D segmenter folder (`sray bench segmenter`): the fleet comparison then includes "
                               "2d-transfer, whose requirement it is (every registered method whose requirements are "
                               "met is compared)")
    accuracy.add_argument("--step-times", action="store_true",
                          help="also time one pretraining step of every stored variant side by side (fresh "
                               "processes, alternating) and chart zero-shot mIoU against it")
    accuracy.add_argument("--out", type=Path, default=None,
                          help="work folder, reused by later runs (default: outputs/bench-accuracy/<preset>)")
    accuracy.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    accuracy.set_defaults(func=_lab_accuracy)


def _lab_accuracy(args: argparse.Namespace) -> int:
    from sray.lab.accuracy.run import run_accuracy_benchmark
    from sray.lab.accuracy.cells import cell_errors
    from sray.lab.accuracy.fleet import compared_methods, fleet_config
    from sray.lab.accuracy.plan import PRESETS, Cell

    try:
        cells = None if args.cells is None else [Cell.parse(c) for c in args.cells]
        unplanned = [c.key for c in cells or [] if c not in PRESETS[args.preset].plan]
        if unplanned:
            raise ValueError(f"{', '.join(unplanned)} not in the {args.preset} plan "
                             f"({', '.join(c.key for c in PRESETS[args.preset].plan)})")
    except ValueError as e:
        print(f"sray lab accuracy: --cells: {e}", file=sys.stderr)
        return 2
    try:  # a given segmenter that does not load stops the command before any cell runs
        compared_methods(fleet_config(PRESETS[args.preset], args.segmenter))
    except FileNotFoundError as e:
        print(f"sray lab accuracy: --segmenter: {e}", file=sys.stderr)
        return 2
    out = args.out or Path("outputs/bench-accuracy") / args.preset
    run_accuracy_benchmark(args.preset, out, args.doc, cells, args.max_minutes, fleet=not args.no_fleet,
                           step_times=args.step_times, segmenter=args.segmenter)
    failed = cell_errors(out)
    if failed:
        print(f"sray lab accuracy: cells {', '.join(failed)} failed (errors in the tables); a re-run runs them "
              "again", file=sys.stderr)
    return 1 if failed else 0
