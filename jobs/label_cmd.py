"""``sray label``: semantic labels for every frame of a capture (or any scene), one tracked run (docs/capture.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sray.jobs.methods.flags import add_tracked_run_flags, print_tracked_run, refuse


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray label``."""
    p = sub.add_parser("label", help="label every frame of a capture: label maps, overlays, confidence, depth, "
                                     "a fly-through",
                       description="Render every frame of each scene from its nearest other frames with a trained "
                                   "checkpoint and write OUT/<scene>/{label,overlay,confidence,depth}/<view>.png, "
                                   "labels.json (sources; mIoU against the stored labels of a labelled scene) and "
                                   "a fly-through through the scene's cameras, as one tracked run (docs/capture.md).")
    p.add_argument("--checkpoint", type=Path, required=True,
                   help="checkpoint folder (…/checkpoints/step_XXXXXXXXX), a job's checkpoints/ or a job folder")
    p.add_argument("--data", type=Path, required=True, help="shard folder holding manifest.json (`sray data shard`)")
    p.add_argument("--out", type=Path, required=True, help="output folder (one sub-folder per scene)")
    p.add_argument("--scenes", nargs="+", metavar="SCENE", help="scenes to label (default: every scene)")
    p.add_argument("--n-source", type=int, default=8, help="source frames per frame, nearest first (default 8)")
    p.add_argument("--render", choices=["full", "fast"], default="fast",
                   help="fast (default): the fast render mode of `sray eval`; full: coarse + fine at every pixel")
    p.add_argument("--flythrough-frames", type=int, default=60,
                   help="frames of each scene's fly-through (default 60; 0: none)")
    add_tracked_run_flags(p, "sray-label")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Check the request, label, print where everything went; exit 2 on bad input."""
    from sray.platform.label.labeller import load
    from sray.platform.label.run import chosen_scenes, label_scenes, tracked_labels

    try:
        if args.flythrough_frames < 0:
            raise ValueError(f"--flythrough-frames is {args.flythrough_frames}; give 0 (none) or more")
        scenes = chosen_scenes(args.data, args.scenes)
        labeller = load(args.checkpoint, args.n_source, args.render, args.device)
        if args.no_track:
            result = {"scenes": label_scenes(labeller, args.data, scenes, args.out, args.flythrough_frames)}
        else:
            result = tracked_labels(labeller, args.data, scenes, args.out, args.flythrough_frames,
                                    tracker=args.tracker, tracking_uri=args.tracking_uri, experiment=args.experiment)
    except (FileNotFoundError, ValueError) as e:
        return refuse("label", e)
    for scene, record in result["scenes"].items():
        scores = record.get("scores")
        line = f"mIoU {100 * scores['miou']:.1f} against its labels" if scores else "no labels to score against"
        print(f"[sray] {scene}: {len(record['frames'])} frames -> {args.out / scene} ({line})")
        if "flythrough" in record:
            print(f"[sray]   fly-through: {record['flythrough']['mp4']}")
    print_tracked_run(result)
    return 0
