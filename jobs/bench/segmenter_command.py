"""``sray bench segmenter``: train the 2D segmenter that ``2d-transfer`` (and the lab's ceilings rows) read, or take
S-Ray's own from a checkpoint."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(kinds: argparse._SubParsersAction) -> None:
    """Add ``segmenter`` to ``sray bench``'s sub-benchmarks."""
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


def _bench_segmenter(args: argparse.Namespace) -> int:
    from sray.jobs.bench.segmenter import run_segmenter
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
