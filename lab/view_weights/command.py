"""``sray lab view-weights``: what the weight net gives source views occluded at the true surface, one row per
checkpoint (docs/benchmarks.md's section "Ceilings")."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(kinds: argparse._SubParsersAction) -> None:
    """Add ``view-weights`` to ``sray lab``'s commands."""
    weights = kinds.add_parser("view-weights", help="what the weight net gives source views occluded at the true "
                               "surface, one row per checkpoint, on zero-shot's views and sources")
    weights.add_argument("--checkpoint", type=Path, nargs="+", required=True,
                         help="checkpoint folders written by `sray train` (one table row each)")
    weights.add_argument("--data", type=Path, required=True, help="shard folder with unseen test scenes")
    weights.add_argument("--n-source", type=int, default=8, help="fixed source views per test view (as sray eval)")
    weights.add_argument("--views-per-scene", type=int, default=0, help="first test views per scene (0: all)")
    weights.add_argument("--stride", type=int, default=2, help="every STRIDE-th pixel in each direction")
    weights.add_argument("--tolerance", type=float, default=0.05,
                         help="visibility test: relative depth agreement of a source's depth with the point")
    weights.add_argument("--out", type=Path, default=Path("outputs/bench-ceilings"), help="folder of view-weights.json")
    weights.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    weights.set_defaults(func=_lab_view_weights)


def _lab_view_weights(args: argparse.Namespace) -> int:
    from sray.lab.view_weights.report import run_view_weights

    try:
        run_view_weights(args.checkpoint, args.data, args.out, args.doc, n_source=args.n_source,
                         views_per_scene=args.views_per_scene, stride=args.stride, tolerance=args.tolerance)
    except ValueError as e:
        print(f"sray lab view-weights: {e}", file=sys.stderr)
        return 2
    return 0
