"""``sray eval``: zero-shot scores of a registered method's pretrained model on unseen scenes (the paper's protocol);
a flag the method does not read (``eval_reads``) is refused, never ignored."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from sray.jobs.methods.flags import GivenFlag, add_tracker_flags, print_tracked_run, refusal, refuse, unread_flags
from sray.jobs.render_flags import add_held_out_flags, held_out_from_args
from sray.platform.finetune.methods.method import EvalRequest
from sray.platform.finetune.methods.registry import eval_method_names, get_method


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray eval``."""
    p = sub.add_parser("eval", help="score a pretrained model on unseen scenes: metrics.json, PNGs, a tracked run")
    p.add_argument("--method", default="sray", choices=eval_method_names(),
                   help="registered method to score (default sray; sray-rgbd: the checkpoint given the source depth, "
                        "RGB-D; 2d-transfer: a 2D segmenter's source labels carried by the source depth, RGB-D)")
    p.add_argument("--checkpoint", type=Path, action=GivenFlag,
                   help="checkpoint folder (…/checkpoints/step_XXXXXXXXX) written by `sray train` (methods sray, "
                        "sray-rgbd)")
    p.add_argument("--segmenter", type=Path, action=GivenFlag,
                   help="2D segmenter folder written by `sray bench segmenter` (method 2d-transfer)")
    p.add_argument("--data", type=Path, required=True, help="shard folder holding manifest.json")
    p.add_argument("--scenes", nargs="+", metavar="SCENE",
                   help="scenes to evaluate (default: every scene whose role is 'test')")
    add_held_out_flags(p, scored_stride=True)
    p.add_argument("--out", type=Path, default=Path("outputs/eval"), help="output folder")
    add_tracker_flags(p, "mlflow")
    p.add_argument("--experiment", default="sray-eval", help="experiment name")
    p.add_argument("--device", help="torch device (default: cuda if available, else cpu)")
    p.add_argument("--calibrate", type=Path, action=GivenFlag, metavar="VAL_SHARDS",
                   help="fast mode: fit the temperature on these validation rooms' test views first (coarse pass, "
                        "NLL; `sray data synth --split validation`), use it, and write OUT/calibration.json")
    p.add_argument("--split", action="append", default=[], metavar="NAME=DIR",
                   help="also score the same model on another shard folder, e.g. appearance-shift=worlds/app/shards "
                        "(repeatable; `sray data synth --split`); the splits are printed side by side with the gap "
                        "from --data's mIoU and written to OUT/splits.json, each split's files under OUT/NAME")
    p.set_defaults(func=run, given=())


def run(args: argparse.Namespace) -> int:
    """Evaluate, print the table and where everything went; exit 2 on bad input (an unread flag included)."""
    from sray.platform.eval.split_gap import SPLITS_FILE, format_splits, split_summary
    from sray.platform.eval.zero_shot import (CALIBRATION_FILE, calibrate, evaluate_model, format_table,
                                              write_json_atomic)

    method = get_method(args.method)
    unread = unread_flags(args.given, method.eval_reads)
    if unread:
        return refuse("eval", refusal(unread, f"--method {method.name}", method.eval_reads))
    splits = dict(item.split("=", 1) for item in args.split if "=" in item)
    if len(splits) != len(args.split) or "" in splits:
        return refuse("eval", f"--split takes NAME=DIR with distinct names, got {args.split}")
    try:
        held_out = held_out_from_args(args)
        request = EvalRequest(checkpoint=args.checkpoint, segmenter=args.segmenter, device=args.device,
                              fast=held_out.fast())
        model = method.eval_model(request)
        if args.calibrate is not None:
            fitted = calibrate(model, args.calibrate, n_source=held_out.n_source)
            write_json_atomic(fitted, args.out / CALIBRATION_FILE)
            print(f"[sray] coarse confidence temperature {fitted['temperature']:.3f} (NLL {fitted['nll_at_1']:.3f} -> "
                  f"{fitted['nll_fitted']:.3f} on {fitted['rays']} rays of {fitted['rooms']} validation rooms)")
            held_out.fast_temperature = fitted["temperature"]
            model = method.eval_model(dataclasses.replace(request, fast=held_out.fast()))
        kwargs = dict(n_source=held_out.n_source, stride=held_out.stride, tracking_uri=args.tracking_uri,
                      experiment=args.experiment, tracker=args.tracker)
        report = evaluate_model(model, args.data, args.scenes, args.out, **kwargs)
        others = {name: evaluate_model(model, Path(folder), None, args.out / name, **kwargs)
                  for name, folder in splits.items()}
    except (FileNotFoundError, ValueError) as e:
        return refuse("eval", e)
    print(format_table(report))
    if others:
        summary = split_summary({"data": report, **others})
        write_json_atomic(summary, args.out / SPLITS_FILE)
        print(format_splits(summary))
        print(f"[sray] splits: {args.out / SPLITS_FILE}")
    print(f"[sray] metrics: {report['metrics_path']}")
    print(f"[sray] renders: {Path(report['out_dir']) / 'renders'}")
    print_tracked_run(report)
    return 0
