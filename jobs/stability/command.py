"""``sray stability``: stress every registered method's rows (zero-shot, and trained on the scene at one CPU-second
budget) along each axis and chart where each breaks; points stored as they finish, so a re-run computes the rest."""

from __future__ import annotations

import argparse
import os
import shutil
from pathlib import Path

from sray.jobs.methods.flags import add_tracker_flags, refuse
from sray.platform.common.bench_doc import Bench, bench_dir, record
from sray.platform.finetune.methods.registry import method_names
from sray.platform.stability.axes import AXES, PRESETS
from sray.platform.stability.rows import MODES


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray stability``."""
    p = sub.add_parser("stability", help="where the registered methods break (zero-shot, and trained on the scene at "
                                         "one CPU budget): charts and tables")
    p.add_argument("--checkpoint", type=Path, metavar="FOLDER",
                   help="S-Ray checkpoint to stress (zero-shot rows; the shared model of the trained rows); default: "
                        "the preset builds its world and pretrains every model")
    p.add_argument("--checkpoint-no-cra", type=Path, metavar="FOLDER",
                   help="S-Ray checkpoint trained with model.attention=none: adds the zero-shot 'without CRA' row")
    p.add_argument("--segmenter", type=Path, metavar="FOLDER",
                   help="2D segmenter of method 2d-transfer (written by `sray bench segmenter`)")
    p.add_argument("--data", type=Path, help="shard folder with unseen test scenes (default: the shards --checkpoint "
                                             "was trained on; without --checkpoint, the preset's own world)")
    p.add_argument("--axes", nargs="+", choices=list(AXES), default=list(AXES), help="axes to run (default: all)")
    p.add_argument("--methods", nargs="+", choices=method_names(), default=method_names(),
                   help="registered methods whose rows are stressed (default: every one)")
    p.add_argument("--modes", nargs="+", choices=list(MODES), default=list(MODES),
                   help="zero-shot rows, rows trained on the scene, or both (default)")
    p.add_argument("--preset", choices=list(PRESETS), default="cpu-small", help="levels, seeds and budgets")
    p.add_argument("--scenes", nargs="+", metavar="SCENE", help="test scenes (default: every role 'test' scene)")
    p.add_argument("--out", type=Path, help="output folder (default: outputs/stability/<preset>)")
    add_tracker_flags(p, "mlflow", store="the output folder")
    p.add_argument("--experiment", default="sray-stability", help="experiment name")
    p.add_argument("--doc", type=Path, default=Path("docs/benchmarks.md"), help="benchmarks document to update")
    p.add_argument("--device", help="torch device (default: cuda if available, else cpu)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the suite and write its outputs; exit 2 on bad input."""
    from sray.jobs.stability.suite_job import StabilityJob, prepare, run_job

    try:
        job = StabilityJob.from_args(args)
        suite, rows = prepare(job)
    except (FileNotFoundError, ValueError) as e:
        return refuse("stability", e)
    outputs = run_job(job, suite, rows)
    _record(job, outputs)
    print(f"[sray] results: {outputs['json']}")
    print(f"[sray] charts: {', '.join(str(c) for c in outputs['charts'])}")
    print(f"[sray] tracked: parent run {outputs['parent_run']} in experiment {job.experiment!r}")
    return 0


def _record(job: object, outputs: dict) -> None:
    """The preset's section of ``docs/benchmarks.md``: a table per axis, the breaking points, the charts."""
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
