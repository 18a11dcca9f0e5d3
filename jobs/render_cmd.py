"""``sray render``: fly-through videos of a scene (colour, semantic labels, depth, confidence side by side)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sray.jobs.data.convert import size_arg
from sray.jobs.methods.flags import add_tracked_run_flags, print_tracked_run, refuse
from sray.jobs.render_flags import add_held_out_flags, held_out_from_args

DEFAULT_FRAMES = 60


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray render``."""
    p = sub.add_parser("render", help="fly-through videos of a scene: RGB, semantics, depth, confidence",
                       description="Render a camera path through a scene with a pretrained checkpoint (or a scene's "
                                   "finetuned artifact): WebM, MP4, GIF preview, frames.json and the protocol line, "
                                   "logged as artifacts of a tracked run (docs/render.md).")
    p.add_argument("--checkpoint", type=Path, required=True,
                   help="checkpoint folder (…/checkpoints/step_XXXXXXXXX), a job's checkpoints/ or a job folder")
    p.add_argument("--data", type=Path, required=True, help="shard folder holding manifest.json")
    p.add_argument("--scene", required=True, help="scene to render (a name in the manifest)")
    p.add_argument("--out", type=Path, default=Path("outputs/render"), help="output folder (default %(default)s)")
    p.add_argument("--artifact", type=Path,
                   help="a scene's S-Ray finetune from `sray finetune-fleet`: <fleet>/scenes/<scene>/sray or its "
                        "sray_delta.safetensors (must come from --checkpoint and --scene)")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--path", choices=["spline", "orbit"], default="spline",
                       help="spline (default): through the scene's source and finetune cameras in capture order; "
                            "orbit: around their centre, looking at it")
    which.add_argument("--camera-path", type=Path, metavar="FILE.json",
                       help="a camera path in nerfstudio's camera_path.json layout (its frames, size and fps)")
    p.add_argument("--frames", type=int, help=f"frames of a built path (default {DEFAULT_FRAMES})")
    p.add_argument("--size", type=size_arg, metavar="WxH",
                   help="render size (default: the scene's image size, or the camera-path file's)")
    p.add_argument("--fps", type=float, help="video frame rate (default: the camera-path file's, else 15)")
    add_held_out_flags(p, scored_stride=False)
    add_tracked_run_flags(p, "sray-render")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Check the request, render, print where the videos went; exit 2 on bad input (nothing written)."""
    import torch

    from sray.platform.finetune.render_model import render_model
    from sray.platform.render.flythrough import Flythrough
    from sray.platform.render.plan import plan_flythrough
    from sray.platform.render.tracked import tracked_flythrough

    try:
        if args.camera_path is not None and args.frames is not None:
            raise ValueError(f"--frames: {args.camera_path} lists its own frames; --frames applies to --path only")
        held_out = held_out_from_args(args)
        plan = plan_flythrough(args.data, args.scene, path=args.path, camera_path=args.camera_path,
                               n_frames=args.frames or DEFAULT_FRAMES, size_hw=args.size, fps=args.fps)
        net, about = render_model(args.checkpoint, args.artifact, args.scene)
        fly = Flythrough(net, plan, held_out.n_source, held_out.fast())
        try:
            device = torch.device(args.device or ("cuda" if torch.cuda.is_available() else "cpu"))
        except RuntimeError as e:
            raise ValueError(f"--device {args.device!r}: {e}") from None
    except (FileNotFoundError, ValueError) as e:
        return refuse("render", e)
    label = "finetuned" if args.artifact is not None else "zero-shot"
    if args.no_track:
        result = fly.render(args.out, device, about=about, label=label)
    else:
        result = tracked_flythrough(fly, args.out, device, about=about, label=label, tracker=args.tracker,
                                    tracking_uri=args.tracking_uri, experiment=args.experiment)
    print(f"[sray] {result['n_frames']} frames at {result['frames_per_s']:.2f} frames/s; protocol: "
          f"{fly.protocol.describe()}")
    print(f"[sray] videos: {result['files']['webm']}  {result['files']['mp4']}  {result['files']['gif']}")
    print_tracked_run(result)
    return 0
