"""``sray stability``: stress S-Ray (full CRA), S-Ray without CRA and Semantic-NeRF along each axis and
chart where each breaks (:mod:`sray.platform.stability`).

Without ``--data`` and ``--checkpoint`` a preset builds its own world (:mod:`sray.jobs.stability.world`).
Points are stored as they finish under ``--out``, so an axis-by-axis run (``--axes pose_noise``) or a
re-run after an interruption computes only what is missing. Tables go into the preset's section of
``docs/benchmarks.md`` (``--doc``): one table per axis plus the breaking points with the charts.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

from sray.jobs.bench.doc import Bench, bench_dir, record
from sray.platform.stability.axes import ALL_METHODS, AXES
from sray.platform.stability.presets import PRESETS

CHECKPOINT_NAMES = {"full": "sray", "none": "sray-no-cra"}
"""``--checkpoint NAME=PATH`` names -> the suite's S-Ray methods."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray stability``."""
    p = sub.add_parser("stability", help="where S-Ray, S-Ray without CRA and Semantic-NeRF break: charts and tables")
    p.add_argument("--data", type=Path, help="shard folder with unseen test scenes (default: the preset's own world)")
    p.add_argument("--checkpoint", action="append", default=[], metavar="NAME=PATH",
                   help="pretrained S-Ray checkpoint: full=PATH (full CRA) and none=PATH (attention=none); "
                        "default: the preset pretrains both")
    p.add_argument("--axes", nargs="+", choices=list(AXES), default=list(AXES), help="axes to run (default: all)")
    p.add_argument("--methods", nargs="+", choices=list(ALL_METHODS), default=list(ALL_METHODS),
                   help="methods to stress (default: all three)")
    p.add_argument("--preset", choices=list(PRESETS), default="cpu-small", help="levels, seeds and budgets")
    p.add_argument("--scenes", nargs="+", metavar="SCENE", help="test scenes (default: every role 'test' scene)")
    p.add_argument("--out", type=Path, help="output folder (default: outputs/stability/<preset>)")
    p.add_argument("--tracker", default="mlflow", help="tracker to log to, by registry name (default: mlflow)")
    p.add_argument("--tracking-uri", help="the tracker's store (default: SQLite store in the output folder)")
    p.add_argument("--experiment", default="sray-stability", help="experiment name")
    p.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"), help="benchmarks document to update")
    p.add_argument("--device", help="torch device (default: cuda if available, else cpu)")
    p.set_defaults(func=run)


def parse_checkpoints(values: list[str]) -> dict[str, Path]:
    """``["full=A", "none=B"]`` -> ``{"sray": A, "sray-no-cra": B}``; ValueError names the bad entry."""
    out = {}
    for value in values:
        name, sep, path = value.partition("=")
        if not sep or name not in CHECKPOINT_NAMES:
            raise ValueError(f"--checkpoint {value!r}: write NAME=PATH with NAME one of {sorted(CHECKPOINT_NAMES)}")
        if not Path(path).exists():
            raise ValueError(f"--checkpoint {value!r}: {path} does not exist; pass a checkpoint folder written by "
                             "`sray train` (…/checkpoints/step_XXXXXXXXX)")
        out[CHECKPOINT_NAMES[name]] = Path(path)
    return out


def run(args: argparse.Namespace) -> int:
    """Run the suite and write its outputs; exit 2 on bad input."""
    from sray.jobs.stability.suite_job import StabilityJob, run_job

    try:
        job = StabilityJob.from_args(args, parse_checkpoints(args.checkpoint))
    except (FileNotFoundError, ValueError) as e:
        print(f"sray stability: {e}", file=sys.stderr)
        return 2
    outputs = run_job(job)
    _record(job, outputs)
    print(f"[sray] results: {outputs['json']}")
    print(f"[sray] charts: {', '.join(str(c) for c in outputs['charts'])}")
    print(f"[sray] tracked: parent run {outputs['parent_run']} in experiment {job.experiment!r}")
    return 0


def _record(job: object, outputs: dict) -> None:
    """The preset's section of ``docs/benchmarks.md``: one table per axis, then the breaking points with the
    charts (copied beside the section's data)."""
    preset, doc = job.preset.name, job.doc
    bench = Bench(f"stability-{preset}", f"Stability, {preset}")
    figures = bench_dir(doc, bench)
    figures.mkdir(parents=True, exist_ok=True)
    links = []
    for chart in outputs["charts"]:
        shutil.copy(chart, figures / chart.name)
        links.append(f"![{chart.stem}]({os.path.relpath(figures / chart.name, doc.parent)})")
    footer = "\n\n".join(outputs["notes"])
    for axis in outputs["axes"]:
        record(bench, axis.replace("_", " ").capitalize(), outputs["tables"][axis], doc, footer)
    summary = "\n".join(f"- {line}" for line in outputs["breaking"])
    record(bench, "Where each method loses half its clean mIoU", summary, doc, footer + "\n\n" + "\n".join(links))
