"""``sray lab``: the studies and diagnostics, a plug-in of the ``sray`` command.

The product's CLI (``sray.jobs.cli``) imports nothing of the lab: it loads the entry points of the group
``sray.commands`` (pyproject.toml names :func:`register` there), so ``sray lab …`` exists where the lab is installed
and the product runs without it. Each module of :data:`LAB_COMMAND_MODULES` adds its commands to ``sray lab`` and
imports what they run inside their entry functions, so ``sray --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib

LAB_COMMAND_MODULES = ("sray.lab.studies.command", "sray.lab.ceilings.command",
                       "sray.lab.view_weights.command", "sray.lab.recipe.command")
"""Modules that register ``sray lab``'s commands (each exposes ``register(kinds)``), in the order help lists them."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray lab`` and its commands to the ``sray`` parser's sub-commands ``sub``."""
    lab = sub.add_parser("lab", help="studies and diagnostics: study spec files, ceilings, view weights, recipe cards")
    kinds = lab.add_subparsers(dest="lab", required=True, metavar="COMMAND")
    for name in LAB_COMMAND_MODULES:
        importlib.import_module(name).register(kinds)
