"""``sray data convert``: one scan or rendered sequence -> sray layout; the formats come from the reader registry."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from sray.data_tools.label_spaces import LABEL_SPACES
from sray.data_tools.readers.registry import READERS


def size_arg(text: str) -> tuple[int, int]:
    """``WxH`` (e.g. ``320x240``) -> (H, W); argparse reports anything else."""
    match = re.fullmatch(r"(\d+)x(\d+)", text.strip().lower())
    if not match or min(int(match[1]), int(match[2])) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: give the size as WIDTHxHEIGHT with positive sides, e.g. 320x240")
    return int(match[2]), int(match[1])


def _default_size(size_hw: tuple[int, int] | None) -> str:
    return "the source's size" if size_hw is None else f"{size_hw[1]}x{size_hw[0]}"


def register(verbs: argparse._SubParsersAction) -> None:
    """Add ``sray data convert``, with the formats, defaults and reader options of the reader registry."""
    formats = "; ".join(f"{r.name}: {r.summary}" for r in READERS.values())
    p = verbs.add_parser("convert", help=f"convert one source scene ({', '.join(READERS)}) into sray layout",
                         description=f"Convert one scan or rendered sequence into one scene of an sray dataset "
                                     f"({formats}). See docs/data.md, 'Readers and validation'.")
    p.add_argument("src", type=Path, help="the scan / sequence folder")
    p.add_argument("--format", required=True, choices=tuple(READERS), help=f"source format ({formats})")
    p.add_argument("--out", required=True, type=Path, help="dataset folder that receives the scene")
    p.add_argument("--name", default=None, help="scene name (default: the source folder's name)")
    p.add_argument("--role", default="train", choices=("train", "test"),
                   help="train: all views, every --holdout-every-th held out as 'test'; "
                        "test: 20-view window, 8 source / 8 finetune / 4 test")
    p.add_argument("--label-space", default="scannet20", choices=tuple(LABEL_SPACES))
    p.add_argument("--size", type=size_arg, default=None, metavar="WxH",
                   help="output size (default: " +
                        ", ".join(f"{_default_size(r.size_hw)} for {r.name}" for r in READERS.values()) + ")")
    p.add_argument("--frame-skip", type=int, default=None, metavar="N",
                   help="keep every N-th usable frame (default: " +
                        ", ".join(f"{r.frame_skip} for {r.name}" for r in READERS.values()) + ")")
    p.add_argument("--depth-scale", type=float, default=1000.0,
                   help="depth PNG units per metre in the source (default 1000: millimetres)")
    shared: dict[str, dict[str, list[str]]] = {}  # option -> its help -> the readers giving that help
    types = {}
    for reader in READERS.values():
        for option in reader.options:
            shared.setdefault(option.name, {}).setdefault(option.help, []).append(reader.name)
            types[option.name] = option.type
    for name, helps in shared.items():
        p.add_argument(f"--{name.replace('_', '-')}", dest=name, type=types[name], default=None,
                       help="; ".join(f"{', '.join(readers)}: {text}" for text, readers in helps.items()))
    p.add_argument("--holdout-every", type=int, default=20, metavar="N",
                   help="train scenes: hold out every N-th view as 'test' (0: none)")
    p.add_argument("--window-start", type=int, default=None, metavar="I",
                   help="test scenes: first view of the 20-view window (default: centred)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing scene of the same name")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Convert; print what was written and which frames were dropped. Exit 1 with the reason on bad input."""
    from tqdm import tqdm

    from sray.data_tools.readers.convert import ConvertConfig, convert_scene

    options = {o.name: getattr(args, o.name) for o in READERS[args.format].options if getattr(args, o.name) is not None}
    cfg = ConvertConfig(format=args.format, src=args.src, out=args.out, name=args.name, role=args.role,
                        label_space=args.label_space, size_hw=args.size, frame_skip=args.frame_skip,
                        depth_scale=args.depth_scale, options=options,
                        holdout_every=args.holdout_every, window_start=args.window_start,
                        overwrite=args.overwrite)
    bar = tqdm(desc=f"sray data convert {args.src}", unit="view", file=sys.stderr)

    def on_view(total: int) -> None:
        bar.total = total
        bar.update()

    try:
        report = convert_scene(cfg, on_view)
    except (OSError, ValueError) as e:
        bar.close()
        print(f"sray data convert: {e}", file=sys.stderr)
        return 1
    bar.close()
    splits = ", ".join(f"{k} {v}" for k, v in report.splits.items())
    print(f"wrote {report.scene_dir}: {report.n_views} views ({splits}), near {report.near:.3f} m, "
          f"far {report.far:.3f} m")
    if report.dropped_frames:
        n = len(report.dropped_frames)
        print(f"dropped {n} source frame{'s' * (n != 1)}:")
        for frame, reason in report.dropped_frames.items():
            print(f"  frame {frame}: {reason}")
    return 0
