"""``sray bench ceilings|view-weights|segmenter``: the arguments and handlers of the benchmarks that say where
accuracy is lost (their tables go into docs/benchmarks.md's section "Ceilings")."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(kinds: argparse._SubParsersAction) -> None:
    """Add ``ceilings``, ``view-weights`` and ``segmenter`` to ``sray bench``'s sub-benchmarks."""
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
    ceilings.set_defaults(func=_bench_ceilings)

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
    weights.set_defaults(func=_bench_view_weights)

    segmenter = kinds.add_parser("segmenter", help="train the 2D segmenter (encoder + linear head) of the ceilings "
                                 "rows for a CPU-second budget on the train scenes' source views, or take S-Ray's "
                                 "own from a checkpoint")
    segmenter.add_argument("--data", type=Path, default=None, help="shard folder with train scenes")
    segmenter.add_argument("--cpu-seconds", type=float, default=None,
                           help="training budget in CPU seconds of this process (time.process_time)")
    segmenter.add_argument("--from-checkpoint", type=Path, default=None, metavar="CHECKPOINT",
                           help="instead of training: write this S-Ray checkpoint's encoder and source-view head "
                           "as the segmenter (no --data, --cpu-seconds or --set)")
    segmenter.add_argument("--out", type=Path, required=True, help="folder the segmenter is saved in")
    segmenter.add_argument("--recipe", default="synth-cpu-hour",
                           help="recipe whose augmentation, class balance and source counts the training uses")
    segmenter.add_argument("--seed", type=int, default=0)
    segmenter.add_argument("--max-steps", type=int, default=None,
                           help="stop after this many steps even within the budget (default: the budget alone)")
    segmenter.add_argument("--encoder-width", type=int, default=None, help="channels of the encoder's first layer, "
                           "every later layer scaled with it (default: the recipe's model.encoder_width)")
    segmenter.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                           help="override a field of the recipe the training reads (repeatable), e.g. "
                           "--set data.aug.colour_ev=0")
    segmenter.set_defaults(func=_bench_segmenter)


def _bench_ceilings(args: argparse.Namespace) -> int:
    from sray.jobs.bench.ceilings import run_ceilings
    from sray.platform.eval.ceilings import ZERO_SHOT_RENDER

    try:
        run_ceilings(args.checkpoint, args.data, args.out, args.doc, n_source=args.n_source,
                     views_per_scene=args.views_per_scene, segmenter=args.segmenter, probe_steps=args.probe_steps,
                     probe_views=args.probe_views, tolerance=args.tolerance,
                     render=ZERO_SHOT_RENDER if args.render == "fast" else None, held_out=args.held_out)
    except ValueError as e:
        print(f"sray bench ceilings: {e}", file=sys.stderr)
        return 2
    return 0


def _bench_view_weights(args: argparse.Namespace) -> int:
    from sray.jobs.bench.view_weights import run_view_weights

    try:
        run_view_weights(args.checkpoint, args.data, args.out, args.doc, n_source=args.n_source,
                         views_per_scene=args.views_per_scene, stride=args.stride, tolerance=args.tolerance)
    except ValueError as e:
        print(f"sray bench view-weights: {e}", file=sys.stderr)
        return 2
    return 0


def _bench_segmenter(args: argparse.Namespace) -> int:
    from sray.jobs.bench.ceilings import run_segmenter
    from sray.platform.eval.segmenter import segmenter_from_checkpoint

    if args.from_checkpoint is not None:
        if args.data is not None or args.cpu_seconds is not None or args.overrides:
            print("sray bench segmenter: --from-checkpoint takes the trained network of a checkpoint; drop --data, "
                  "--cpu-seconds and --set, or drop --from-checkpoint to train one", file=sys.stderr)
            return 2
        try:
            _, record = segmenter_from_checkpoint(args.from_checkpoint, args.out)
        except (ValueError, FileNotFoundError) as e:
            print(f"sray bench segmenter: {e}", file=sys.stderr)
            return 2
        print(f"segmenter saved in {args.out}: {record.budget()}")
        return 0
    if args.data is None or args.cpu_seconds is None:
        print("sray bench segmenter: give --data SHARDS and --cpu-seconds S to train a segmenter, or "
              "--from-checkpoint CHECKPOINT to take S-Ray's own", file=sys.stderr)
        return 2
    try:
        run_segmenter(args.data, args.cpu_seconds, args.out, args.recipe, args.seed, args.max_steps,
                      args.encoder_width, tuple(args.overrides))
    except ValueError as e:
        print(f"sray bench segmenter: {e}", file=sys.stderr)
        return 2
    return 0
