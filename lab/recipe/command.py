"""``sray lab recipe-step``, ``sray lab recipe-cards`` and ``sray lab demo-result``: where a recipe's step spends its
CPU, the recipe cards regenerated from stored results (README and docs/benchmarks.md), and a finished demo stored as
the run the README's ``synth-demo`` card is published from."""

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

    demo = kinds.add_parser("demo-result", help="store a finished `sray demo` run, read from its output folder, as "
                            "jobs/studies/results/demo/make-demo--s<seed>.json (the README's synth-demo card and the "
                            "demo's time are published from it)")
    demo.add_argument("out", type=Path, metavar="OUTPUTS_DIR", help="the demo's --out folder, e.g. outputs/demo")
    demo.add_argument("--finetune-seconds", type=float, default=60.0,
                      help="the demo's --finetune-seconds (its fleet's wall budget per room; default 60, the demo's)")
    demo.add_argument("--results", type=Path, default=None,
                      help="folder of the stored demo runs (default jobs/studies/results/demo)")
    demo.set_defaults(func=_lab_demo_result)


def _lab_recipe_cards(args: argparse.Namespace) -> int:
    from sray.lab.recipe.cards import run_recipe_cards

    try:
        run_recipe_cards(args.results, args.readme, args.doc)
    except ValueError as e:
        print(f"sray lab recipe-cards: {e}", file=sys.stderr)
        return 2
    print(f"[bench] recipe cards written into {args.readme} and {args.doc}")
    return 0


def _lab_demo_result(args: argparse.Namespace) -> int:
    from sray.lab.recipe.demo_result import RESULTS_DIR, write_demo_result
    from sray.lab.recipe.results import MissingField

    try:
        path = write_demo_result(args.out, args.results or RESULTS_DIR, args.finetune_seconds)
    except (ValueError, MissingField) as e:
        print(f"sray lab demo-result: {e}", file=sys.stderr)
        return 2
    print(f"[demo] stored {path}; publish it with `python -m sray.lab.publish`")
    return 0


def _lab_recipe_step(args: argparse.Namespace) -> int:
    from sray.lab.recipe.step import run_recipe_step

    try:
        run_recipe_step(args.recipe, args.data, args.lever, args.steps, args.rounds, args.warm_up, args.doc, args.phase)
    except (FileNotFoundError, ValueError) as e:
        print(f"sray lab recipe-step: {e}", file=sys.stderr)
        return 2
    return 0
