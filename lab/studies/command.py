"""``sray lab study SPEC.yaml``: run a study's missing trials on the sweep engine; ``--page``: regenerate its page
from the stored results (docs/sweeps.md, "Studies")."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

DEFAULT_OUT = "outputs/studies"
"""Work folder of the studies (worlds, training jobs, evaluations, the engine's records) unless ``--out`` says."""


def register(kinds: argparse._SubParsersAction) -> None:
    """Add ``study`` to ``sray lab``'s commands."""
    study = kinds.add_parser("study", help="run a study spec file (jobs/studies/*.yaml): one trial per arm and seed, "
                             "resumable, results stored beside it; --page writes docs/studies/<study>.md")
    study.add_argument("spec", type=Path, help="the study file, e.g. jobs/studies/hour-levers.yaml")
    study.add_argument("--page", action="store_true",
                       help="train nothing: regenerate the study's page and chart from its stored results (the "
                            "page's Reading is kept)")
    study.add_argument("--worlds", action="store_true",
                       help="train nothing: generate the shards of every world the study names under OUT/worlds/")
    study.add_argument("--docs", type=Path, default=Path("docs"), help="docs folder the page goes under (studies/)")
    study.add_argument("--out", type=Path, default=Path(DEFAULT_OUT), help=f"work folder (default {DEFAULT_OUT})")
    study.add_argument("--max-minutes", type=float, default=None, help="start no trial after this many minutes")
    study.add_argument("--tracking-uri", default="",
                       help="tracker store (default: a SQLite store in the study's work folder)")
    study.add_argument("--address", help="join this Ray cluster (default: start Ray locally in-process)")
    study.add_argument("--dry-run", action="store_true", help="list the trials that would run, run nothing")
    study.set_defaults(func=_lab_study)


def _lab_study(args: argparse.Namespace) -> int:
    from sray.lab.studies.page import write_page
    from sray.lab.studies.runner import make_worlds, missing_trials, run_study_spec
    from sray.lab.studies.spec import StudyError, load_study

    try:
        spec = load_study(args.spec)
        if args.page:
            print(f"[study] page written: {write_page(spec, args.docs)}")
            return 0
        if args.worlds:
            print("[study] worlds: " + ", ".join(str(p) for p in make_worlds(spec, args.out)))
            return 0
        todo = missing_trials(spec)
        print(f"[study] {spec.name}: {len(todo)} of {len(spec.trial_keys())} trials to run: "
              f"{', '.join(todo) or 'none'}", flush=True)
        if args.dry_run:
            return 0
        store = args.tracking_uri or f"sqlite:///{(args.out / spec.name).resolve() / 'mlflow.db'}"
        (args.out / spec.name).mkdir(parents=True, exist_ok=True)
        outcomes = run_study_spec(spec, args.out, store, args.address, args.max_minutes)
    except (StudyError, ValueError, FileNotFoundError) as e:
        print(f"sray lab study: {str(e).splitlines()[0]}", file=sys.stderr)
        return 2
    failed = [o.key for o in outcomes if o.reason != "finished"]
    print(f"[study] results in {spec.results_dir}; page: sray lab study --page {args.spec}", flush=True)
    if failed:
        print(f"sray lab study: trials {', '.join(failed)} did not finish; run the study again to continue them",
              file=sys.stderr)
    return 1 if failed else 0
