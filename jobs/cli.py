"""The ``sray`` console script: each subcommand module's ``register(subparsers)`` sets ``func`` (namespace -> exit code)
and imports heavy modules only there, so ``sray --help`` stays fast; plug-ins register via :data:`PLUGIN_GROUP`."""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import sys

SUBCOMMAND_MODULES = ("sray.jobs.data.command", "sray.jobs.train_cmd", "sray.jobs.submit_cmd", "sray.jobs.eval_cmd",
                      "sray.jobs.render_cmd", "sray.jobs.label_cmd", "sray.jobs.fleet_cmd", "sray.jobs.sweep_cmd",
                      "sray.jobs.bench.command",
                      "sray.jobs.gpu_check.command", "sray.jobs.gpu_bundle.command", "sray.jobs.stability.command",
                      "sray.jobs.demo_cmd", "sray.jobs.ui_cmd", "sray.jobs.cluster_cmd", "sray.jobs.migrate_cmd")
"""Modules that register subcommands, in the order `sray --help` lists them."""
PLUGIN_GROUP = "sray.commands"


def build_parser() -> argparse.ArgumentParser:
    """The full ``sray`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="sray",
        description="Generalizable semantic radiance fields (S-Ray): data, training, finetune fleets, benchmarks.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in SUBCOMMAND_MODULES:
        importlib.import_module(name).register(sub)
    for entry in sorted(importlib.metadata.entry_points(group=PLUGIN_GROUP), key=lambda e: e.name):
        entry.load()(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and run the chosen subcommand; returns its exit code."""
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
