"""``sray bench loader|model|profile|speed-accuracy|segmenter``: the benchmarks a user runs on their own setup; each
table is printed, stored beside its charts and rendered into docs/benchmarks.md (a section per benchmark and device)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sray.jobs.bench.speed_methods import other_methods
from sray.jobs.methods.flags import add_tracker_flags, refuse


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray bench`` and its sub-benchmarks."""
    bench = sub.add_parser("bench", help="run a benchmark and write its tables into docs/benchmarks.md")
    kinds = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")

    loader = kinds.add_parser("loader", help="shard loader samples/s and rays/s with 0, 1, 2 DataLoader workers")
    loader.add_argument("--data", type=Path, default=None,
                        help="shard folder (default: generate small procedural shards in a temp folder)")
    loader.add_argument("--batches", type=int, default=30, help="batches timed per setting")
    loader.set_defaults(func=_bench_loader)

    model = kinds.add_parser("model", help="CRA vs dense attention cost; training-step time and memory")
    model.add_argument("--device", default="auto", help="cpu, cuda or auto")
    model.add_argument("--quick", action="store_true", help="smaller sizes (for tests)")
    model.add_argument("--tables", nargs="+", default=["attention", "train"], choices=["attention", "train"],
                       help="which tables to measure (attention cost, training step)")
    model.add_argument("--official-side-by-side", type=Path, default=None, metavar="RESULTS_JSON",
                       help="results.json of a same-run side-by-side of the official S-Ray code and sray "
                            "(the shared tools' official_side_by_side/run.py): adds its table to the section")
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
                       help="measure only these settings, by their table names, the first being the row the others are "
                            "compared with (default: all; a chosen set replaces the 'chosen settings' table and chart)")
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
    add_tracker_flags(speed, "mlflow", "")
    speed.set_defaults(func=_bench_speed_accuracy)
    for table_bench in (loader, model, prof, speed):
        table_bench.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))

    segmenter = kinds.add_parser("segmenter", help="train the 2D segmenter (encoder + linear head) of the ceilings "
                                 "rows for a CPU-second budget on the train scenes' source views, or take S-Ray's "
                                 "own from a checkpoint")
    segmenter.add_argument("--data", type=Path, default=None, help="shard folder with train scenes")
    segmenter.add_argument("--cpu-seconds", type=float, default=None,
                           help="training budget in CPU seconds of this process (time.process_time)")
    segmenter.add_argument("--from-checkpoint", type=Path, default=None, metavar="CHECKPOINT",
                           help="instead of training: write this S-Ray checkpoint's encoder and source-view head "
                           "as the segmenter (no --data, --cpu-seconds or --set)")
    segmenter.add_argument("--out", type=Path, required=True, help="folder the segmenter is saved in")
    segmenter.add_argument("--recipe", default="synth-cpu-hour",
                           help="recipe whose augmentation, class balance and source counts the training uses")
    segmenter.add_argument("--seed", type=int, default=0)
    segmenter.add_argument("--max-steps", type=int, default=None,
                           help="stop after this many steps even within the budget (default: the budget alone)")
    segmenter.add_argument("--encoder-width", type=int, default=None, help="channels of the encoder's first layer, "
                           "every later layer scaled with it (default: the recipe's model.encoder_width)")
    segmenter.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                           help="override a field of the recipe the training reads (repeatable), e.g. "
                           "--set data.aug.colour_ev=0")
    segmenter.set_defaults(func=_bench_segmenter)


def _bench_profile(args: argparse.Namespace) -> int:
    from sray.jobs.bench.probes import resolve_device
    from sray.jobs.bench.profile import run_profiles, write_profiles

    write_profiles(run_profiles(resolve_device(args.device), tuple(args.impl), tuple(args.workload), args.quick),
                   args.doc)
    return 0


def _bench_speed_accuracy(args: argparse.Namespace) -> int:
    from sray.jobs.bench.speed_accuracy_run import run_speed_accuracy

    try:
        run_speed_accuracy(args.checkpoint, args.data, args.views_per_scene, args.doc, args.tracker,
                           args.tracking_uri, args.checkpoint_rgbd, args.settings, args.methods, args.segmenter,
                           args.store)
    except (FileNotFoundError, ValueError) as e:
        return refuse("bench speed-accuracy", e)
    return 0


def _bench_loader(args: argparse.Namespace) -> int:
    from sray.jobs.bench.loader_throughput import LOADER, run_loader_benchmark
    from sray.platform.common.bench_doc import record

    title, table, notes = run_loader_benchmark(args.data, batches=args.batches)
    record(LOADER, title, table, args.doc, notes)
    return 0


def _bench_model(args: argparse.Namespace) -> int:
    from sray.jobs.bench.model_cost import MODEL, official_side_by_side, run_model_benchmark
    from sray.platform.common.bench_doc import record

    sections = run_model_benchmark(device=args.device, quick=args.quick, tables=tuple(args.tables))
    if args.official_side_by_side is not None:
        sections.append(official_side_by_side(args.official_side_by_side))
    for title, table, notes in sections:
        record(MODEL, title, table, args.doc, notes)
    return 0


def _bench_segmenter(args: argparse.Namespace) -> int:
    from sray.jobs.bench.segmenter import run_segmenter
    from sray.platform.eval.segmenter import segmenter_from_checkpoint

    if args.from_checkpoint is not None:
        if args.data is not None or args.cpu_seconds is not None or args.overrides:
            return refuse("bench segmenter", "--from-checkpoint takes the trained network of a checkpoint; drop "
                          "--data, --cpu-seconds and --set, or drop --from-checkpoint to train one")
        try:
            _, record = segmenter_from_checkpoint(args.from_checkpoint, args.out)
        except (ValueError, FileNotFoundError) as e:
            return refuse("bench segmenter", e)
        print(f"segmenter saved in {args.out}: {record.budget()}")
        return 0
    if args.data is None or args.cpu_seconds is None:
        return refuse("bench segmenter", "give --data SHARDS and --cpu-seconds S to train a segmenter, or "
                      "--from-checkpoint CHECKPOINT to take S-Ray's own")
    try:
        run_segmenter(args.data, args.cpu_seconds, args.out, args.recipe, args.seed, args.max_steps,
                      args.encoder_width, tuple(args.overrides))
    except ValueError as e:
        return refuse("bench segmenter", e)
    return 0
