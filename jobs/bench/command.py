"""``sray bench loader|model|profile|recipe-step|speed-accuracy|accuracy|ceilings|view-weights|segmenter|recipe-cards``:
measured tables, printed, stored as data beside their charts and rendered into docs/benchmarks.md (one section per
benchmark and device); ``recipe-cards`` reads stored results into the README's cards as well."""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

from sray.jobs.bench.speed_methods import other_methods

BENCH_SUBCOMMAND_MODULES = ("sray.jobs.bench.ceilings_command",)
"""Modules that register more sub-benchmarks (each exposes ``register(kinds)``), listed after ``accuracy``."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray bench`` and its sub-benchmarks."""
    bench = sub.add_parser("bench", help="run a benchmark and write its tables into docs/benchmarks.md")
    kinds = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")

    loader = kinds.add_parser("loader", help="shard loader samples/s and rays/s with 0, 1, 2 DataLoader workers")
    loader.add_argument("--data", type=Path, default=None,
                        help="shard folder (default: generate small procedural shards in a temp folder)")
    loader.add_argument("--batches", type=int, default=30, help="batches timed per setting")
    loader.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    loader.set_defaults(func=_bench_loader)

    model = kinds.add_parser("model", help="CRA vs dense attention cost; training-step time and memory")
    model.add_argument("--device", default="auto", help="cpu, cuda or auto")
    model.add_argument("--quick", action="store_true", help="smaller sizes (for tests)")
    model.add_argument("--tables", nargs="+", default=["attention", "train"], choices=["attention", "train"],
                       help="which tables to measure (attention cost, training step)")
    model.add_argument("--official-side-by-side", type=Path, default=None, metavar="RESULTS_JSON",
                       help="results.json of a same-run side-by-side of the official S-Ray code and sray "
                            "(the shared tools' official_side_by_side/run.py): adds its table to the section")
    model.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    model.set_defaults(func=_bench_model)

    prof = kinds.add_parser("profile", help="torch.profiler of the training step and of a whole-image render")
    prof.add_argument("--device", default="auto", help="cpu, cuda or auto")
    prof.add_argument("--impl", nargs="+", default=["reference", "fast"], choices=["reference", "fast"],
                      help="implementations to profile (runtime.impl)")
    prof.add_argument("--workload", nargs="+", default=["train", "render"],
                      choices=["train", "render", "kernels", "train-kernels", "chunks", "attention-keys"],
                      help="train/render: torch.profiler tables; kernels/chunks: the render's levers, timed; "
                           "train-kernels: the attention kernels forward + backward at the training step's shapes; "
                           "attention-keys: SDPA flash against the sliced CPU kernel by key length")
    prof.add_argument("--quick", action="store_true", help="tiny sizes (for tests)")
    prof.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    prof.set_defaults(func=_bench_profile)

    speed = kinds.add_parser("speed-accuracy", help="mIoU (overall and per class) and PSNR against seconds per view "
                             "(Pareto chart); the default render chosen by the rule")
    speed.add_argument("--checkpoint", type=Path, required=True, action="append",
                       help="checkpoint folder written by `sray train`; repeat it (e.g. a recipe's seeds) to apply the "
                            "default-render rule to each and to their mean")
    speed.add_argument("--data", type=Path, required=True, help="shard folder with unseen test scenes")
    speed.add_argument("--checkpoint-rgbd", type=Path, default=None,
                       help="a checkpoint trained with model.inputs=rgbd for the rgbd settings "
                            "(default: --checkpoint's weights rendered with the source depth)")
    speed.add_argument("--views-per-scene", type=int, default=2,
                       help="test views rendered per scene and setting (0: every test view)")
    speed.add_argument("--settings", nargs="+", default=None, metavar="NAME",
                       help="measure only these settings, by their table names, the first being the row the others "
                            "are compared with (default: all; a chosen set replaces the 'chosen settings' table "
                            "and chart)")
    speed.add_argument("--methods", nargs="+", default=[], choices=other_methods(), metavar="METHOD",
                       help="also time these registered methods' zero-shot models (choices: "
                            f"{', '.join(other_methods())}), each on the same views and sources as S-Ray's setting "
                            "of its inputs, listed beside it ('full, rgbd' is added for an RGB-D method when the "
                            "settings lack one); never offered to the default-render rule")
    speed.add_argument("--segmenter", type=Path, default=None,
                       help="2D segmenter folder (`sray bench segmenter`) for a method of --methods that reads one "
                            "(2d-transfer)")
    speed.add_argument("--store", type=Path, default=None, metavar="FOLDER",
                       help="keep every measured row here (per checkpoint and setting); a re-run with the same folder "
                            "reads the rows it holds instead of measuring them again, so a long run resumes")
    speed.add_argument("--tracker", default="mlflow")
    speed.add_argument("--tracking-uri", default="", help="tracker store (default: SQLite store in this folder)")
    speed.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    speed.set_defaults(func=_bench_speed_accuracy)

    accuracy = kinds.add_parser("accuracy", help="zero-shot mIoU with seeds (resumable cells), the attention "
                                "ablation, the registered per-scene methods at equal finetune budgets")
    accuracy.add_argument("--preset", choices=["cpu-small", "gpu"], default="cpu-small",
                          help="cpu-small: 2 CPU cores, over several runs of about an hour; gpu: for a GPU machine")
    accuracy.add_argument("--cells", nargs="+", default=None, metavar="VARIANT:SEED",
                          help="run only these cells of the preset's plan, e.g. long:0 full:1 (default: every "
                               "missing one)")
    accuracy.add_argument("--max-minutes", type=float, default=None,
                          help="start no new cell after this many minutes (the tables are written either way)")
    accuracy.add_argument("--no-fleet", action="store_true", help="skip the finetune comparison")
    accuracy.add_argument("--segmenter", type=Path, default=None,
                          help="2D segmenter folder (`sray bench segmenter`): the fleet comparison then includes "
                               "2d-transfer, whose requirement it is (every registered method whose requirements are "
                               "met is compared)")
    accuracy.add_argument("--step-times", action="store_true",
                          help="also time one pretraining step of every stored variant side by side (fresh "
                               "processes, alternating) and chart zero-shot mIoU against it")
    accuracy.add_argument("--out", type=Path, default=None,
                          help="work folder, reused by later runs (default: outputs/bench-accuracy/<preset>)")
    accuracy.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    accuracy.set_defaults(func=_bench_accuracy)

    for name in BENCH_SUBCOMMAND_MODULES:
        importlib.import_module(name).register(kinds)

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
    step.set_defaults(func=_bench_recipe_step)

    cards = kinds.add_parser("recipe-cards", help="regenerate the recipe cards (their benchmark page) from "
                             "stored results: time, memory and accuracy of every recipe on every machine")
    cards.add_argument("--results", type=Path, required=True, metavar="LIST_JSON",
                       help="JSON list of each recipe's stored results per machine (format: docs/benchmarks.md, "
                            "'Recipe cards'); paths relative to its folder")
    cards.add_argument("--readme", type=Path, default=None,
                       help="also write the table between this file's recipe-cards markers (the repository's README "
                            "publishes its cards with `python -m sray.lab.publish` instead)")
    cards.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    cards.set_defaults(func=_bench_recipe_cards)


def _bench_recipe_cards(args: argparse.Namespace) -> int:
    from sray.jobs.bench.recipe_cards import run_recipe_cards

    try:
        run_recipe_cards(args.results, args.readme, args.doc)
    except ValueError as e:
        print(f"sray bench recipe-cards: {e}", file=sys.stderr)
        return 2
    print(f"[bench] recipe cards written into {args.readme} and {args.doc}")
    return 0


def _bench_recipe_step(args: argparse.Namespace) -> int:
    from sray.jobs.bench.recipe_step import run_recipe_step

    try:
        run_recipe_step(args.recipe, args.data, args.lever, args.steps, args.rounds, args.warm_up, args.doc, args.phase)
    except (FileNotFoundError, ValueError) as e:
        print(f"sray bench recipe-step: {e}", file=sys.stderr)
        return 2
    return 0


def _bench_accuracy(args: argparse.Namespace) -> int:
    from sray.jobs.bench.accuracy import run_accuracy_benchmark
    from sray.jobs.bench.accuracy_cells import cell_errors
    from sray.jobs.bench.accuracy_fleet import compared_methods, fleet_config
    from sray.jobs.bench.accuracy_plan import PRESETS, Cell

    try:
        cells = None if args.cells is None else [Cell.parse(c) for c in args.cells]
        unplanned = [c.key for c in cells or [] if c not in PRESETS[args.preset].plan]
        if unplanned:
            raise ValueError(f"{', '.join(unplanned)} not in the {args.preset} plan "
                             f"({', '.join(c.key for c in PRESETS[args.preset].plan)})")
    except ValueError as e:
        print(f"sray bench accuracy: --cells: {e}", file=sys.stderr)
        return 2
    try:  # a given segmenter that does not load stops the command before any cell runs
        compared_methods(fleet_config(PRESETS[args.preset], args.segmenter))
    except FileNotFoundError as e:
        print(f"sray bench accuracy: --segmenter: {e}", file=sys.stderr)
        return 2
    out = args.out or Path("outputs/bench-accuracy") / args.preset
    run_accuracy_benchmark(args.preset, out, args.doc, cells, args.max_minutes, fleet=not args.no_fleet,
                           step_times=args.step_times, segmenter=args.segmenter)
    failed = cell_errors(out)
    if failed:
        print(f"sray bench accuracy: cells {', '.join(failed)} failed (errors in the tables); a re-run runs them "
              "again", file=sys.stderr)
    return 1 if failed else 0


def _bench_profile(args: argparse.Namespace) -> int:
    from sray.jobs.bench.model_cost import resolve_device
    from sray.jobs.bench.profile import run_profiles, write_profiles

    sections = run_profiles(resolve_device(args.device), tuple(args.impl), tuple(args.workload), args.quick)
    write_profiles(sections, args.doc)
    return 0


def _bench_speed_accuracy(args: argparse.Namespace) -> int:
    from sray.jobs.bench.speed_accuracy_run import run_speed_accuracy

    try:
        run_speed_accuracy(args.checkpoint, args.data, args.views_per_scene, args.doc, args.tracker,
                           args.tracking_uri, args.checkpoint_rgbd, args.settings, args.methods, args.segmenter,
                           args.store)
    except (FileNotFoundError, ValueError) as e:
        print(f"sray bench speed-accuracy: {e}", file=sys.stderr)
        return 2
    return 0


def _bench_loader(args: argparse.Namespace) -> int:
    from sray.jobs.bench.doc import record
    from sray.jobs.bench.loader_throughput import LOADER, run_loader_benchmark

    title, table, notes = run_loader_benchmark(args.data, batches=args.batches)
    record(LOADER, title, table, args.doc, notes)
    return 0


def _bench_model(args: argparse.Namespace) -> int:
    from sray.jobs.bench.doc import record
    from sray.jobs.bench.model_cost import MODEL, run_model_benchmark
    from sray.jobs.bench.official_code import official_side_by_side

    sections = run_model_benchmark(device=args.device, quick=args.quick, tables=tuple(args.tables))
    if args.official_side_by_side is not None:
        sections.append(official_side_by_side(args.official_side_by_side))
    for title, table, notes in sections:
        record(MODEL, title, table, args.doc, notes)
    return 0
