"""``sray data stats DIR``: per-class pixel frequencies of a dataset (scene folders) or a shard folder."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray data stats`` to the ``sray data`` verbs."""
    p = sub.add_parser("stats", help="per-class pixel frequencies of a dataset or shard folder",
                       description="Count the pixels of every class (and of the ignore id) over a dataset's scenes "
                                   "(sray layout) or a shard folder (with manifest.json), and print, per class, its "
                                   "share of all pixels, of the labelled pixels, and in how many scenes it occurs.")
    p.add_argument("path", type=Path, help="dataset folder (sray layout) or shard folder")
    p.add_argument("--roles", nargs="+", default=["train", "test"], choices=["train", "test"],
                   help="scene roles to count (default: both)")
    p.set_defaults(func=_run)


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


def _run(args: argparse.Namespace) -> int:
    from sray.data_tools.loader.class_stats import dataset_pixel_counts, shard_pixel_counts

    roles = tuple(args.roles)
    if (args.path / "manifest.json").exists():
        names, per_scene = shard_pixel_counts(args.path, roles)
    else:
        names, per_scene = dataset_pixel_counts(args.path, roles)
    print(format_stats(names, per_scene))
    return 0
