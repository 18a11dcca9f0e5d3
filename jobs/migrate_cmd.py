"""``sray migrate PATH``: convert an earlier sray's artifacts under PATH to today's format (loads refuse old ones)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sray.jobs.methods.flags import refuse


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray migrate``."""
    p = sub.add_parser("migrate", help="convert the checkpoints, configs, sweeps, scene artifacts and "
                       "segmenters of an earlier sray",
                       description="Convert every stored artifact of an earlier sray under PATH (a checkpoint folder, "
                                   "a job, sweep, fleet or segmenter folder, or any folder above them) to "
                                   "today's format, in place and atomically; nothing is written unless all of them "
                                   "convert.")
    p.add_argument("path", type=Path, metavar="PATH", help="file or folder to convert (searched recursively)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Convert, print one line per artifact; exit 2 (nothing written) when an artifact cannot be converted."""
    from sray.platform.migrate.artifacts import find_conversions
    from sray.platform.migrate.config_formats import MigrationRefused

    try:
        conversions = find_conversions(args.path)
    except MigrationRefused as e:
        return refuse("migrate", e)
    for conversion in conversions:
        conversion.write()
        print(f"[sray] migrated {conversion.what}: {conversion.path}")
    if not conversions:
        print(f"[sray] {args.path}: already in today's format, nothing to do")
    return 0
