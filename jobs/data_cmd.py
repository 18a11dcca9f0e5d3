"""``sray data synth|convert|check|shard``: from whatever a user has to validated shards."""

from __future__ import annotations

import argparse
import importlib

DATA_SUBCOMMAND_MODULES = (
    "sray.jobs.data_synth_cmd",
    "sray.jobs.data_convert_cmd",
    "sray.jobs.data_check_cmd",
    "sray.jobs.data_shard_cmd",
)
"""Each module exposes ``register(subparsers)`` for one ``sray data`` verb."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray data`` and its verbs."""
    data = sub.add_parser("data", help="generate, convert, check and shard scenes")
    verbs = data.add_subparsers(dest="data_command", required=True, metavar="VERB")
    for name in DATA_SUBCOMMAND_MODULES:
        importlib.import_module(name).register(verbs)
