"""One ``sray stability`` job: its inputs checked up front, the world built or read, the suite run, and the
outputs written over every axis whose points are all stored (so axis-by-axis runs add up to one table)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from sray.data_tools.scene import IGNORE_ID
from sray.jobs.stability.world import world_checkpoints, world_shards
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.eval.zero_shot import select_scenes
from sray.platform.stability.axes import AXES, SOURCE_METHODS
from sray.platform.stability.point_trial import SuiteInputs
from sray.platform.stability.points_study import point_records, run_points
from sray.platform.stability.presets import PRESETS, Preset
from sray.platform.stability.report import track, write_outputs
from sray.platform.stability.suite import planned_points
from sray.platform.tracking.registry import get_tracker


@dataclass
class StabilityJob:
    """Everything a stability run needs, validated."""

    preset: Preset
    axes: list[str]
    methods: list[str]
    out: Path
    doc: Path
    shards: Path | None = None
    """None: the preset builds its own world under ``out``."""
    checkpoints: dict[str, Path] = field(default_factory=dict)
    scenes: list[str] | None = None
    tracker: str = "mlflow"
    tracking_uri: str | None = None
    experiment: str = "sray-stability"
    device: str | None = None

    @classmethod
    def from_args(cls, args: argparse.Namespace, checkpoints: dict[str, Path]) -> StabilityJob:
        """The job of parsed CLI arguments; ValueError names the flag and the fix."""
        preset = PRESETS[args.preset]
        if args.data is None and checkpoints:
            raise ValueError("--checkpoint needs --data (the shards the checkpoints are scored on); leave both out "
                             "to let the preset build its world and pretrain both variants")
        if args.data is not None:
            if not (Path(args.data) / "manifest.json").exists():
                raise ValueError(f"--data {args.data}: no manifest.json there; pass a folder written by "
                                 "`sray data shard`")
            missing = [m for m in SOURCE_METHODS if m in args.methods and m not in checkpoints]
            if missing:
                names = {v: k for k, v in {"full": "sray", "none": "sray-no-cra"}.items()}
                raise ValueError(f"--data given without checkpoints for {missing}: add "
                                 + " ".join(f"--checkpoint {names[m]}=PATH" for m in missing)
                                 + " or leave those methods out with --methods")
        methods = [m for m in args.methods if any(m in AXES[a].methods for a in args.axes)]
        if not methods:
            raise ValueError(f"--axes {args.axes} apply to none of --methods {args.methods}")
        out = args.out or Path("outputs/stability") / preset.name
        return cls(preset=preset, axes=list(args.axes), methods=methods, out=Path(out).resolve(), doc=args.doc,
                   shards=None if args.data is None else Path(args.data).resolve(), checkpoints=checkpoints,
                   scenes=args.scenes, tracker=args.tracker, tracking_uri=args.tracking_uri,
                   experiment=args.experiment, device=args.device)


def _check_checkpoints(checkpoints: dict[str, Path]) -> tuple[int | None, int | None, str]:
    """The checkpoints' label space (classes, ignore id) and source inputs (``model.inputs``, ``rgb`` when there
    is none); ValueError when the checkpoints disagree on either."""
    classes, inputs = set(), set()
    for path in checkpoints.values():
        _, cfg = model_from_checkpoint(path)
        classes.add((cfg.model.n_classes, cfg.model.ignore_id))
        inputs.add(cfg.model.inputs)
    if len(classes) > 1:
        raise ValueError(f"checkpoints {sorted(map(str, checkpoints.values()))} predict different label spaces "
                         f"{sorted(classes)}; pretrain both variants on the same data")
    if len(inputs) > 1:
        raise ValueError(f"checkpoints {sorted(map(str, checkpoints.values()))} mix model.inputs {sorted(inputs)}; "
                         "compare variants trained with the same inputs")
    n_classes, ignore_id = next(iter(classes)) if classes else (None, None)
    return n_classes, ignore_id, next(iter(inputs)) if inputs else "rgb"


def run_job(job: StabilityJob) -> dict[str, Any]:
    """Run the suite; returns :func:`~sray.platform.stability.report.write_outputs`'s dict plus ``parent_run``."""
    job.out.mkdir(parents=True, exist_ok=True)
    tracking_uri = job.tracking_uri or f"sqlite:///{job.out / 'mlflow.db'}"
    shards, checkpoints = job.shards, dict(job.checkpoints)
    if shards is None:
        shards = world_shards(job.preset, job.out)
        checkpoints = world_checkpoints(job.preset, shards, job.out, tracking_uri, job.methods)
    names, metas = select_scenes(shards, job.scenes)
    device = torch.device(job.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    n_classes, ignore_id, inputs = _check_checkpoints(checkpoints)
    scene_classes = {len(m["class_names"]) for m in metas.values()}
    if n_classes is not None and scene_classes != {n_classes}:
        raise ValueError(f"{shards / 'manifest.json'}: scenes have {sorted(scene_classes)} classes, the checkpoints "
                         f"predict {n_classes}; score them on data of their own label space")
    suite = SuiteInputs(job.preset, str(shards), tuple(names), tuple((m, str(p)) for m, p in checkpoints.items()),
                        n_classes or scene_classes.pop(), IGNORE_ID if ignore_id is None else ignore_id, str(device))
    outcomes = run_points(job.out, planned_points(job.preset, job.axes, job.methods), suite)
    errors = {o.key: o.note for o in outcomes if o.reason == "errored"}
    done = [a for a in AXES if point_records(job.out, job.preset, planned_points(job.preset, [a], job.methods), errors)]
    records = point_records(job.out, job.preset, planned_points(job.preset, done, job.methods), errors)
    protocol = EvalProtocol.from_shards(shards, job.preset.n_source, job.preset.eval_stride, inputs).describe()
    extra = {"shards": str(shards), "checkpoints": {m: str(p) for m, p in checkpoints.items()},
             "scenes": names, "methods": job.methods}
    outputs = write_outputs(records, job.preset, done, protocol, job.out, extra)
    tracker = get_tracker(job.tracker, tracking_uri)
    run_name = f"stability-{job.preset.name}-{job.out.name}"
    outputs["parent_run"] = track(tracker, job.experiment, run_name, outputs, records, done, job.preset)
    outputs["axes"] = done
    return outputs
