"""``sray demo``: the README's main job on the embedded defaults (its stages: :mod:`sray.jobs.demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from sray.platform.config.recipes import DEMO_STEPS


SEGMENTER_CPU_CAP = 60.0
"""Uncapped, the segmenter would get the CPU seconds of S-Ray's training, minutes more on a 2-core machine."""
TRAIN_SCENES = 19
"""4 + 5k training rooms keep the 4-room world's two test rooms file for file (room types cycle over the index); 19
lift zero-shot mIoU where 4 do not (study ``demo-recipe``)."""
FLEET_SCENES = 1
"""Each fleet scene costs four finetunes (minutes on a 2-core machine): the demo finetunes one, evaluates all."""


def _cpu_cap(text: str) -> float:
    """``--segmenter-cpu-seconds``: CPU seconds >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of CPU seconds") from None
    if not value >= 0:  # also refuses nan
        raise argparse.ArgumentTypeError(f"{text} CPU seconds: give 0 (no cap) or more")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray demo``."""
    p = sub.add_parser("demo", help="the main job: scenes -> shards -> a short training run (local Ray)")
    p.add_argument("--out", type=Path, default=Path("outputs/demo"), help="output folder")
    p.add_argument("--train-scenes", type=int, default=TRAIN_SCENES)
    p.add_argument("--test-scenes", type=int, default=2)
    p.add_argument("--views", type=int, default=40, help="views per scene")
    p.add_argument("--height", type=int, default=120)
    p.add_argument("--width", type=int, default=160)
    p.add_argument("--steps", type=int, default=DEMO_STEPS,
                   help="training steps of the synth-demo recipe, its first third on source-view labels alone "
                        "(0 = data only)")
    p.add_argument("--segmenter-cpu-seconds", type=_cpu_cap, default=SEGMENTER_CPU_CAP, metavar="S",
                   help="2d-transfer's 2D segmenter trains for the CPU seconds S-Ray's training spent, but at most S "
                        f"(default {SEGMENTER_CPU_CAP:.0f}: about half a minute on 2 cores, so the demo stays near 10 "
                        "minutes); 0 = no cap, equal CPU")
    p.add_argument("--finetune-seconds", type=float, default=60.0,
                   help="wall-clock budget of each per-scene finetune (every method)")
    p.add_argument("--fleet-scenes", type=int, default=FLEET_SCENES,
                   help=f"the fleet finetunes the first N unseen scenes (default {FLEET_SCENES}; 0 = every one); the "
                        "zero-shot evaluation scores them all")
    p.add_argument("--eval-stride", type=int, default=2,
                   help="score every n-th pixel in each direction in the zero-shot evaluation (the fleet's held-out "
                        "curves use twice this); 1 = full images, the only stride with SSIM")
    p.add_argument("--clip-frames", type=int, default=24,
                   help="frames of the zero-shot fly-through video rendered after the evaluation")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the demo (``sray.jobs.demo``); exit 1 if the data fails its checks."""
    from sray.jobs.demo import run_demo

    return run_demo(args)
