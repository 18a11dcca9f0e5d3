"""``sray lab ceilings``: where zero-shot (or held-out) accuracy is lost, as a table (docs/benchmarks.md's section
"Ceilings")."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(kinds: argparse._SubParsersAction) -> None:
    """Add ``ceilings`` to ``sray lab``'s commands."""
    ceilings = kinds.add_parser("ceilings", help="where zero-shot (or held-out) accuracy is lost: label-transfer "
                                "ceilings, the field at the true surface and linear probes, on zero-shot's views and "
                                "sources")
    ceilings.add_argument("--checkpoint", type=Path, required=True, help="checkpoint folder written by `sray train`")
    ceilings.add_argument("--data", type=Path, required=True, help="shard folder with unseen test scenes")
    ceilings.add_argument("--held-out", type=int, default=0, metavar="N",
                          help="score the held-out views of the first N training scenes by name (the accuracy "
                               "benchmark's held-out rule) instead of the unseen test scenes: where fitting is lost")
    ceilings.add_argument("--n-source", type=int, default=8, help="fixed source views per test view (as sray eval)")
    ceilings.add_argument("--views-per-scene", type=int, default=0, help="first test views per scene (0: all)")
    ceilings.add_argument("--segmenter", type=Path, default=None,
                          help="2D segmenter folder (`sray bench segmenter`); without it rows b, c and c-rgb are "
                               "left out")
    ceilings.add_argument("--probe-steps", type=int, default=300, help="Adam steps of each linear probe's fit")
    ceilings.add_argument("--probe-views", type=int, default=64, help="train-scene views the probes are fitted on")
    ceilings.add_argument("--tolerance", type=float, default=0.05,
                          help="occlusion test: relative depth agreement of a source's depth with the point")
    ceilings.add_argument("--render", choices=["full", "fast"], default="fast",
                          help="S-Ray's render in rows s and c-rgb: fast (default), the accuracy benchmark's zero-shot "
                               "render (every pixel, fine pass below 0.9 confidence); full: the whole renderer")
    ceilings.add_argument("--out", type=Path, default=Path("outputs/bench-ceilings"), help="folder of ceilings.json")
    ceilings.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    ceilings.set_defaults(func=_lab_ceilings)


def _lab_ceilings(args: argparse.Namespace) -> int:
    from sray.lab.ceilings.report import run_ceilings
    from sray.lab.ceilings.measure import ZERO_SHOT_RENDER

    try:
        run_ceilings(args.checkpoint, args.data, args.out, args.doc, n_source=args.n_source,
                     views_per_scene=args.views_per_scene, segmenter=args.segmenter, probe_steps=args.probe_steps,
                     probe_views=args.probe_views, tolerance=args.tolerance,
                     render=ZERO_SHOT_RENDER if args.render == "fast" else None, held_out=args.held_out)
    except ValueError as e:
        print(f"sray lab ceilings: {e}", file=sys.stderr)
        return 2
    return 0
