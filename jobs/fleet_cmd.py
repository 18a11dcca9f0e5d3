"""``sray finetune-fleet``: the registry's per-scene methods (S-Ray finetune, Semantic-NeRF, ...) as Ray tasks."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from sray.jobs.methods.flags import add_tracker_flags, refuse
from sray.platform.finetune.methods.registry import METHODS, method_names

ALL_METHODS = "all"


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray finetune-fleet``."""
    p = sub.add_parser("finetune-fleet", help="per-scene finetunes as Ray tasks, one parent tracked run",
                       description="Run per-scene methods on each scene's finetune views (finetune the shared S-Ray "
                                   "model, train Semantic-NeRF from scratch, ...), with early stopping on the "
                                   "held-out views. A re-launch with the same --out skips finished scenes.")
    p.add_argument("--checkpoint", required=True, type=Path,
                   help="shared S-Ray checkpoint: a step_XXXXXXXXX folder, a job's checkpoints/ or a job folder")
    p.add_argument("--data", required=True, type=Path, help="shard folder (manifest.json)")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--scenes", nargs="+", metavar="SCENE", help="scenes to finetune (any with 'test' views)")
    which.add_argument("--all-test", action="store_true", help="every unseen test scene of --data")
    summaries = "; ".join(f"{m.name}: {m.summary}" for m in METHODS.values())
    p.add_argument("--methods", "--method", dest="methods", nargs="+", choices=[*METHODS, ALL_METHODS],
                   default=["sray"], metavar="METHOD",
                   help=f"methods run per scene, default sray ({summaries}; {ALL_METHODS}: every one)")
    p.add_argument("--max-parallel", type=int, help="most scene tasks at once (max_parallel)")
    p.add_argument("--cpus-per-task", type=float, help="CPUs per scene task, fractions allowed")
    p.add_argument("--gpus-per-task", type=float, help="GPUs per scene task, fractions share a GPU")
    p.add_argument("--precision", choices=["no", "bf16", "fp16"], help="autocast (fp16: CUDA only)")
    p.add_argument("--segmenter", help="pretrained 2D segmenter folder of method 2d-transfer, written by `sray bench "
                                       "segmenter` (transfer.segmenter)")
    p.add_argument("--out", type=Path, default=Path("outputs/fleet"), help="fleet folder (default outputs/fleet)")
    add_tracker_flags(p, uri="")
    p.add_argument("--clip-frames", type=int, default=0, metavar="N",
                   help="render an N-frame fly-through per S-Ray scene before and after finetuning, logged to the "
                        "scene's run (default 0: none; docs/render.md)")
    p.add_argument("--address", help="join this Ray cluster (default: start Ray locally in-process)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="[SECTION.]FIELD=VALUE",
                   help="override a fleet config field, e.g. --set finetune.patience=5 (repeatable)")
    p.set_defaults(func=run)


def fleet_flags(args: argparse.Namespace) -> dict[str, Any]:
    """The FleetConfig fields the parsed flags set (``path -> value``, None = not given)."""
    return {"max_parallel": args.max_parallel, "cpus_per_task": args.cpus_per_task,
            "gpus_per_task": args.gpus_per_task, "finetune.precision": args.precision, "address": args.address,
            "tracker": args.tracker, "transfer.segmenter": args.segmenter}


def chosen_methods(values: list[str]) -> list[str]:
    """The methods ``--methods`` asks for: every registered one for ``all``, else the names once each, in order."""
    return method_names() if ALL_METHODS in values else list(dict.fromkeys(values))


def run(args: argparse.Namespace) -> int:
    """Run the fleet; exit 0 when every pair finished, 1 when some failed, 2 for a bad request."""
    from sray.data_tools.shards.manifest import unseen_scenes
    from sray.platform.config.fleet_config import build_fleet_config
    from sray.platform.finetune.fleet import run_fleet
    from sray.platform.train.resources import InfeasibleRequest

    try:
        cfg = build_fleet_config(fleet_flags(args), args.overrides)
        scenes = unseen_scenes(args.data) if args.all_test else args.scenes
        if args.clip_frames < 0:
            raise ValueError(f"--clip-frames is {args.clip_frames}; give 0 (no clips) or a number of frames")
        results = run_fleet(cfg, args.checkpoint, args.data, scenes, args.out, args.tracking_uri,
                            chosen_methods(args.methods), args.clip_frames)
    except (InfeasibleRequest, FileNotFoundError, ValueError) as e:
        return refuse("finetune-fleet", e)
    return 0 if all(r["status"] == "finished" for r in results) else 1
