"""``sray data shard``: checked canonical scenes -> per-scene webdataset shards + manifest.json."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(verbs: argparse._SubParsersAction) -> None:
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
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Shard and/or verify; exit 1 on rejected input or damaged shards, 2 on a usage error."""
    from sray.data_tools.shards.manifest import verify_shards
    from sray.data_tools.shards.writer import DatasetRejected, write_shards

    if args.scenes_dir is None and not args.verify:
        print("sray data shard: give SCENES_DIR to shard, or --verify to check --out", file=sys.stderr)
        return 2
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
