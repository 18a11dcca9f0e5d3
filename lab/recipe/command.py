"""``sray lab recipe-step`` and ``sray lab recipe-cards``: where a recipe's step spends its CPU, and the recipe
cards regenerated from stored results (README and docs/benchmarks.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(kinds: argparse._SubParsersAction) -> None:
    """Add ``recipe-step`` and ``recipe-cards`` to ``sray lab``'s commands."""
    step = kinds.add_parser("recipe-step", help="where a recipe's ray step or 2D warm-up step spends its CPU (loading, "
                            "encoder, fields, backward, Adam) on real shards, beside its step-cost levers")
    step.add_argument("--recipe", default="synth-cpu-hour", help="the recipe whose step is measured")
    step.add_argument("--data", type=Path, required=True, help="shard folder with the recipe's training scenes")
    step.add_argument("--lever", nargs="+", action="append", default=[], metavar=("NAME", "SECTION.FIELD=VALUE"),
                      help="a variant: its name, then its overrides (repeatable): --lever r128 data.rays_per_batch=128")
    step.add_argument("--phase", choices=("rays", "2d"), default="rays", help="a ray step, or a 2D warm-up step")
    step.add_argument("--steps", type=int, default=20, help="measured steps per variant and round")
    step.add_argument("--rounds", type=int, default=3, help="rounds, the variants alternating")
    step.add_argument("--warm-up", type=int, default=3, help="unmeasured steps per variant first")
    step.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    step.set_defaults(func=_lab_recipe_step)

    cards = kinds.add_parser("recipe-cards", help="regenerate the recipe cards (their benchmark page) from "
                             "stored results: time, memory and accuracy of every recipe on every machine")
    cards.add_argument("--results", type=Path, required=True, metavar="LIST_JSON",
                       help="JSON list of each recipe's stored results per machine (format: docs/benchmarks.md, "
                            "'Recipe cards'); paths relative to its folder")
    cards.add_argument("--readme", type=Path, default=None,
                       help="also write the table between this file's recipe-cards markers (the repository's README "
                            "publishes its cards with `python -m sray.lab.publish` instead)")
    cards.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    cards.set_defaults(func=_lab_recipe_cards)


def _lab_recipe_cards(args: argparse.Namespace) -> int:
    from sray.lab.recipe.cards import run_recipe_cards

    try:
        run_recipe_cards(args.results, args.readme, args.doc)
    except ValueError as e:
        print(f"sray lab recipe-cards: {e}", file=sys.stderr)
        return 2
    print(f"[bench] recipe cards written into {args.readme} and {args.doc}")
    return 0


def _lab_recipe_step(args: argparse.Namespace) -> int:
    from sray.lab.recipe.step import run_recipe_step

    try:
        run_recipe_step(args.recipe, args.data, args.lever, args.steps, args.rounds, args.warm_up, args.doc, args.phase)
    except (FileNotFoundError, ValueError) as e:
        print(f"sray lab recipe-step: {e}", file=sys.stderr)
        return 2
    return 0
