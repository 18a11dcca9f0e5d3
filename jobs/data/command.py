"""``sray data synth|convert|check|shard|stats``: from whatever a user has to validated shards."""

from __future__ import annotations

import argparse
import importlib

DATA_SUBCOMMAND_MODULES = (
    "sray.jobs.data.synth",
    "sray.jobs.data.convert",
    "sray.jobs.data.check",
    "sray.jobs.data.shard",
    "sray.jobs.data.stats",
)
"""Each exposes ``register(subparsers)`` for one ``sray data`` verb."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray data`` and its verbs."""
    data = sub.add_parser("data", help="generate, convert, check and shard scenes")
    verbs = data.add_subparsers(dest="data_command", required=True, metavar="VERB")
    for name in DATA_SUBCOMMAND_MODULES:
        importlib.import_module(name).register(verbs)
