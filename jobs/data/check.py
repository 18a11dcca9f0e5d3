"""``sray data check``: list every problem of a dataset in sray layout; exit 1 if there is any."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from sray.data_tools.scene_folder import list_scenes


def register(verbs: argparse._SubParsersAction) -> None:
    """Add ``sray data check``."""
    p = verbs.add_parser("check", help="validate a dataset (or one scene) in sray layout; writes nothing",
                         description="List every problem with the file, what is wrong and how to fix it. "
                                     "Exit status 1 when there is any problem, 0 otherwise.")
    p.add_argument("path", type=Path, help="dataset folder (with dataset.json or scene folders) or one scene folder")
    p.add_argument("--min-train-views", type=int, default=4,
                   help="views a train scene needs in its 'train' split (loader source views + 1)")
    p.add_argument("--min-source-views", type=int, default=2, help="'source' views a test scene needs")
    p.add_argument("--min-test-views", type=int, default=1, help="'test' views a test scene needs")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print problems grouped by file and a count (exit 1), or a one-line OK summary (exit 0)."""
    from sray.data_tools.check.scenes import CheckLimits, check_dataset

    limits = CheckLimits(min_train_views=args.min_train_views, min_source_views=args.min_source_views,
                         min_test_views=args.min_test_views)
    problems = check_dataset(args.path, limits)
    if problems:
        by_file: dict[str, list] = {}
        for p in problems:
            by_file.setdefault(p.file, []).append(p)
        for file, items in by_file.items():
            print(file)
            for p in items:
                print(f"  - {p.what}\n    fix: {p.fix}")
        print(f"{len(problems)} problem{'s' * (len(problems) != 1)} in {len(by_file)} file{'s' * (len(by_file) != 1)}")
        return 1
    scene_files = [args.path / "scene.json"] if (args.path / "scene.json").exists() else \
        [args.path / name / "scene.json" for name in _scene_names(args.path)]
    metas = [json.loads(f.read_text()) for f in scene_files]
    n_views = sum(len(m["view_ids"]) for m in metas)
    unlabelled = sum(m.get("labelled", True) is False for m in metas)
    note = f" ({unlabelled} without labels: inference only, `sray label`)" if unlabelled else ""
    print(f"OK: {len(scene_files)} scene{'s' * (len(scene_files) != 1)}{note}, {n_views} views in {args.path}, "
          "no problems")
    return 0


def _scene_names(root: Path) -> list[str]:
    return [p.name for p in list_scenes(root) if not p.name.startswith(".")]
