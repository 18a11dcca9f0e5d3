"""``sray data synth``: write the embedded default dataset of procedural indoor scenes."""

from __future__ import annotations

import argparse
from pathlib import Path

from sray.data_tools.synth.domains import SPLITS


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray data synth`` to the ``sray data`` verbs."""
    p = sub.add_parser("synth", help="generate procedural indoor scenes (ScanNet-20 labels) in sray layout",
                       description="Render procedural rooms (walls, doors, windows, furniture) along handheld-style "
                                   "camera paths: RGB, metric z-depth, ScanNet-20 labels, intrinsics and poses. "
                                   "Scenes already written with the same parameters are skipped.")
    p.add_argument("--out", type=Path, required=True, help="dataset folder to write (created if missing)")
    p.add_argument("--train-scenes", type=int, default=4, help="number of training scenes (default 4)")
    p.add_argument("--test-scenes", type=int, default=2, help="number of unseen test scenes (default 2)")
    p.add_argument("--views", type=int, default=60, help="views per scene (default 60; test scenes need >= 20)")
    p.add_argument("--height", type=int, default=240, help="image height in pixels (default 240)")
    p.add_argument("--width", type=int, default=320, help="image width in pixels (default 320)")
    p.add_argument("--seed", type=int, default=0, help="dataset seed; same seed, identical files (default 0)")
    p.add_argument("--workers", type=int, default=1,
                   help="scenes rendered at once in separate processes (default 1); files do not depend on it")
    p.add_argument("--split", default="in-distribution",
                   choices=SPLITS,
                   help="region the test scenes are drawn from (default in-distribution; training scenes always are): "
                        "validation rooms, or appearance/geometry held out from every training room (docs/data.md)")
    p.add_argument("--randomise", type=float, default=0.0,
                   help="appearance randomisation of the training scenes, 0-1 (default 0 = off): per-surface colours, "
                        "per-room white balance, per-view exposure, all inside the training region (docs/data.md)")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from sray.data_tools.synth.dataset import generate_dataset

    scenes = generate_dataset(args.out, n_train=args.train_scenes, n_test=args.test_scenes, n_views=args.views,
                              height=args.height, width=args.width, seed=args.seed, progress=True,
                              workers=args.workers, split=args.split, randomise=args.randomise)
    print(f"wrote {len(scenes)} procedural scenes ({args.train_scenes} train, {args.test_scenes} {args.split} test, "
          f"{args.views} views of {args.height}x{args.width}) to {Path(args.out).resolve()}")
    print(f"index: {Path(args.out).resolve() / 'dataset.json'}")
    return 0
