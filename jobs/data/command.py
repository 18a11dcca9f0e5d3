"""``sray data synth|convert|check|shard|stats``: from whatever a user has to validated shards. Convert, whose parser
is built from the reader registry, is a module of its own."""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from pathlib import Path

import numpy as np

from sray.data_tools.scene_folder import list_scenes
from sray.data_tools.synth.domains import SPLITS
from sray.jobs.methods.flags import refuse

DATA_SUBCOMMAND_MODULES = ("sray.jobs.data.convert",)
"""Modules that register a ``sray data`` verb of their own (``register(subparsers)``)."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray data`` and its verbs."""
    data = sub.add_parser("data", help="generate, convert, check and shard scenes")
    verbs = data.add_subparsers(dest="data_command", required=True, metavar="VERB")
    register_synth(verbs)
    for name in DATA_SUBCOMMAND_MODULES:
        importlib.import_module(name).register(verbs)
    register_check(verbs)
    register_shard(verbs)
    register_stats(verbs)


def register_synth(verbs: argparse._SubParsersAction) -> None:
    """Add ``sray data synth``."""
    p = verbs.add_parser("synth", help="generate procedural indoor scenes (ScanNet-20 labels) in sray layout",
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
    p.set_defaults(func=_synth)


def _synth(args: argparse.Namespace) -> int:
    from sray.data_tools.synth.dataset import generate_dataset

    scenes = generate_dataset(args.out, n_train=args.train_scenes, n_test=args.test_scenes, n_views=args.views,
                              height=args.height, width=args.width, seed=args.seed, progress=True,
                              workers=args.workers, split=args.split, randomise=args.randomise)
    print(f"wrote {len(scenes)} procedural scenes ({args.train_scenes} train, {args.test_scenes} {args.split} test, "
          f"{args.views} views of {args.height}x{args.width}) to {Path(args.out).resolve()}")
    print(f"index: {Path(args.out).resolve() / 'dataset.json'}")
    return 0


def register_check(verbs: argparse._SubParsersAction) -> None:
    """Add ``sray data check``."""
    p = verbs.add_parser("check", help="validate a dataset (or one scene) in sray layout; writes nothing",
                         description="List every problem with the file, what is wrong and how to fix it. "
                                     "Exit status 1 when there is any problem, 0 otherwise.")
    p.add_argument("path", type=Path, help="dataset folder (with dataset.json or scene folders) or one scene folder")
    p.add_argument("--min-train-views", type=int, default=4,
                   help="views a train scene needs in its 'train' split (loader source views + 1)")
    p.add_argument("--min-source-views", type=int, default=2, help="'source' views a test scene needs")
    p.add_argument("--min-test-views", type=int, default=1, help="'test' views a test scene needs")
    p.set_defaults(func=_check)


def _check(args: argparse.Namespace) -> int:
    from sray.data_tools.check.scenes import CheckLimits, check_dataset

    limits = CheckLimits(min_train_views=args.min_train_views, min_source_views=args.min_source_views,
                         min_test_views=args.min_test_views)
    problems = check_dataset(args.path, limits)
    if problems:
        by_file: dict[str, list] = {}
        for p in problems:
            by_file.setdefault(p.file, []).append(p)
        for file, items in by_file.items():
            print(file)
            for p in items:
                print(f"  - {p.what}\n    fix: {p.fix}")
        print(f"{len(problems)} problem{'s' * (len(problems) != 1)} in {len(by_file)} file{'s' * (len(by_file) != 1)}")
        return 1
    scene_files = [args.path / "scene.json"] if (args.path / "scene.json").exists() else \
        [p / "scene.json" for p in list_scenes(args.path) if not p.name.startswith(".")]
    metas = [json.loads(f.read_text()) for f in scene_files]
    n_views = sum(len(m["view_ids"]) for m in metas)
    unlabelled = sum(m.get("labelled", True) is False for m in metas)
    note = f" ({unlabelled} without labels: inference only, `sray label`)" if unlabelled else ""
    print(f"OK: {len(scene_files)} scene{'s' * (len(scene_files) != 1)}{note}, {n_views} views in {args.path}, "
          "no problems")
    return 0


def register_shard(verbs: argparse._SubParsersAction) -> None:
    """Add ``sray data shard``."""
    p = verbs.add_parser(
        "shard", help="write webdataset shards (grouped by scene) and manifest.json; --verify checks them",
        description="Shard a dataset in sray layout (it must pass `sray data check`). Re-runs are idempotent: "
                    "unchanged shards are left alone and the output is byte-identical for identical input.")
    p.add_argument("scenes_dir", type=Path, nargs="?", default=None, metavar="SCENES_DIR",
                   help="dataset in sray layout (omit with --verify to only verify --out)")
    p.add_argument("--out", type=Path, required=True, metavar="SHARDS_DIR", help="output shard folder")
    p.add_argument("--views-per-shard", type=int, default=256, help="views per tar shard (a shard never mixes scenes)")
    p.add_argument("--neighbours", type=int, default=32,
                   help="ranked source-view neighbours stored per view (the loader's top-k must not exceed it)")
    p.add_argument("--verify", action="store_true",
                   help="check every shard's size and sha256 against manifest.json (after writing, if SCENES_DIR)")
    p.set_defaults(func=_shard)


def _shard(args: argparse.Namespace) -> int:
    from sray.data_tools.shards.manifest import verify_shards
    from sray.data_tools.shards.writer import DatasetRejected, write_shards

    if args.scenes_dir is None and not args.verify:
        return refuse("data shard", "give SCENES_DIR to shard, or --verify to check --out")
    if args.scenes_dir is not None:
        try:
            result = write_shards(args.scenes_dir, args.out, views_per_shard=args.views_per_shard,
                                  neighbours=args.neighbours)
        except DatasetRejected as e:
            print(e, file=sys.stderr)
            return 1
        m = result.manifest
        print(f"{len(m.scenes)} scenes, {sum(s.n_views for s in m.scenes.values())} views, {len(m.shards)} shards "
              f"({sum(s.bytes for s in m.shards) / 1e6:.1f} MB) in {args.out}: {len(result.written)} written, "
              f"{len(result.unchanged)} unchanged, {len(result.removed)} stale removed")
        unlabelled = sorted(n for n, e in m.scenes.items() if e.meta.get("labelled", True) is False)
        if unlabelled:
            print(f"without labels (inference only: `sray label`; training refuses them): {', '.join(unlabelled)}")
    if args.verify:
        problems = verify_shards(args.out)
        for line in problems:
            print(line, file=sys.stderr)
        if problems:
            print(f"{len(problems)} damaged or missing file(s) in {args.out}", file=sys.stderr)
            return 1
        print(f"verified: every shard in {args.out} matches manifest.json (size and sha256)")
    return 0


def register_stats(verbs: argparse._SubParsersAction) -> None:
    """Add ``sray data stats``."""
    p = verbs.add_parser("stats", help="per-class pixel frequencies of a dataset or shard folder",
                       description="Count the pixels of every class (and of the ignore id) over a dataset's scenes "
                                   "(sray layout) or a shard folder (with manifest.json), and print, per class, its "
                                   "share of all pixels, of the labelled pixels, and in how many scenes it occurs.")
    p.add_argument("path", type=Path, help="dataset folder (sray layout) or shard folder")
    p.add_argument("--roles", nargs="+", default=["train", "test"], choices=["train", "test"],
                   help="scene roles to count (default: both)")
    p.set_defaults(func=_stats)


def format_stats(names: list[str], per_scene: dict[str, np.ndarray]) -> str:
    """The table `sray data stats` prints: class, % of all pixels, % of labelled pixels, scenes present."""
    total = np.sum(list(per_scene.values()), axis=0)
    present = np.sum([c > 0 for c in per_scene.values()], axis=0)
    labelled = max(int(total[:-1].sum()), 1)
    rows = [f"{'class':<16} {'% pixels':>9} {'% labelled':>11} {'scenes':>7}"]
    for i, name in enumerate(names):
        rows.append(f"{name:<16} {100 * total[i] / total.sum():9.2f} {100 * total[i] / labelled:11.2f} "
                    f"{int(present[i]):>4}/{len(per_scene)}")
    rows.append(f"{'(ignore)':<16} {100 * total[-1] / total.sum():9.2f} {'':>11} "
                f"{int(present[-1]):>4}/{len(per_scene)}")
    rows.append(f"{len(per_scene)} scenes, {int(total.sum())} pixels")
    return "\n".join(rows)


def _stats(args: argparse.Namespace) -> int:
    from sray.data_tools.loader.class_stats import dataset_pixel_counts, shard_pixel_counts

    roles = tuple(args.roles)
    if (args.path / "manifest.json").exists():
        names, per_scene = shard_pixel_counts(args.path, roles)
    else:
        names, per_scene = dataset_pixel_counts(args.path, roles)
    print(format_stats(names, per_scene))
    return 0
