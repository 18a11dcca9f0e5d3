"""``sray bench loader|model|accuracy``: measured tables, printed and appended to docs/benchmarks.md."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray bench`` and its sub-benchmarks."""
    bench = sub.add_parser("bench", help="run a benchmark and append its table to docs/benchmarks.md")
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
    model.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    model.set_defaults(func=_bench_model)

    accuracy = kinds.add_parser("accuracy", help="ablation (zero-shot) and S-Ray finetune vs Semantic-NeRF")
    accuracy.add_argument("--preset", choices=["cpu-small", "gpu"], default="cpu-small",
                          help="cpu-small: within an hour on 2 CPU cores; gpu: for a GPU machine")
    accuracy.add_argument("--out", type=Path, default=Path("outputs/bench-accuracy"), help="work folder")
    accuracy.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"))
    accuracy.set_defaults(func=_bench_accuracy)


def _bench_accuracy(args: argparse.Namespace) -> int:
    from sray.jobs.bench.accuracy import run_accuracy_benchmark

    run_accuracy_benchmark(args.preset, args.out, args.doc)
    return 0


def _bench_loader(args: argparse.Namespace) -> int:
    from sray.jobs.bench.doc import record
    from sray.jobs.bench.loader_throughput import run_loader_benchmark

    title, table, notes = run_loader_benchmark(args.data, batches=args.batches)
    record(title, table, args.doc, notes)
    return 0


def _bench_model(args: argparse.Namespace) -> int:
    from sray.jobs.bench.doc import record
    from sray.jobs.bench.model_cost import run_model_benchmark

    for title, table, notes in run_model_benchmark(device=args.device, quick=args.quick):
        record(title, table, args.doc, notes)
    return 0
