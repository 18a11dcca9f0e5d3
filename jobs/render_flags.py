"""The held-out render flags of ``sray eval`` and ``sray render`` (``HeldOutRender``; fast ones :class:`GivenFlag`)."""

from __future__ import annotations

import argparse

from sray.jobs.methods.flags import GivenFlag
from sray.platform.config.held_out_render import HELD_OUT_RENDERS, HeldOutRender

DEFAULTS = HeldOutRender()


def add_held_out_flags(p: argparse.ArgumentParser, scored_stride: bool) -> None:
    """Add the held-out render flags to ``p``, with ``--stride`` for a command that scores pixels."""
    p.add_argument("--n-source", type=int, default=DEFAULTS.n_source,
                   help="fixed source views per view, top-ranked (default %(default)s, the paper's protocol)")
    if scored_stride:
        p.add_argument("--stride", type=int, default=DEFAULTS.stride,
                       help="score every N-th pixel in each direction (1 = whole images; SSIM only then)")
    p.add_argument("--render", choices=HELD_OUT_RENDERS, default=DEFAULTS.render, action=GivenFlag,
                   help="S-Ray's render; fast (default): the fast render mode (sray.model.fast_render; its accuracy "
                        "cost, measured paired against the full render by `sray bench speed-accuracy`, is in "
                        "docs/benchmarks.md); full: the whole coarse + fine renderer at every pixel")
    p.add_argument("--fast-stride", type=int, default=DEFAULTS.fast_stride, action=GivenFlag,
                   help="fast mode: render every N-th pixel and upsample (default %(default)s)")
    p.add_argument("--fast-confidence", type=float, default=DEFAULTS.fast_confidence, action=GivenFlag,
                   help="fast mode: rays whose coarse confidence reaches this skip the fine pass (default %(default)s)")
    p.add_argument("--fast-temperature", type=float, default=DEFAULTS.fast_temperature, action=GivenFlag,
                   help="fast mode: divide the coarse logits by this before the confidence rule (default %(default)s)")


def held_out_from_args(args: argparse.Namespace) -> HeldOutRender:
    """The ``HeldOutRender`` of the parsed flags; ValueError naming the flag and the fix."""
    if args.n_source < 1:
        raise ValueError(f"--n-source is {args.n_source}; give at least one source view")
    settings = HeldOutRender(n_source=args.n_source, stride=getattr(args, "stride", DEFAULTS.stride),
                             render=args.render, fast_stride=args.fast_stride, fast_confidence=args.fast_confidence,
                             fast_temperature=args.fast_temperature)
    settings.check(lambda field: "--" + field.replace("_", "-"))
    return settings

