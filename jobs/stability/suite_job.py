"""One ``sray stability`` job: inputs checked up front; the given models (data: the checkpoint's shards) or the preset's
world pretrained; rows from the method registry; outputs of every axis whose points are all stored (runs add up)."""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from sray.jobs.stability.world import world_models, world_shards
from sray.model.config import SRayConfig
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.eval.zero_shot import select_scenes
from sray.platform.finetune.methods.registry import get_method
from sray.platform.stability.axes import AXES, PRESETS, Preset
from sray.platform.stability.points_study import SuiteInputs, point_records, run_points
from sray.platform.stability.report import track, write_outputs
from sray.platform.stability.rows import Row, SuiteModels, suite_rows
from sray.platform.stability.scene_points import scene_settings
from sray.platform.stability.suite import planned_points
from sray.platform.tracking.registry import get_tracker

MODEL_FLAGS = {"checkpoint": "--checkpoint", "checkpoint_no_cra": "--checkpoint-no-cra", "segmenter": "--segmenter"}


@dataclass
class StabilityJob:
    """Everything a stability run needs, validated."""

    preset: Preset
    axes: list[str]
    methods: list[str]
    modes: list[str]
    """``zero-shot`` and/or ``scene`` (``rows.MODES``)."""
    out: Path
    doc: Path
    given: SuiteModels | None = None
    """The models given on the command line (None: the preset pretrains them)."""
    data: Path | None = None
    """Shards of the test scenes (None: the checkpoint's training shards, or the preset's world)."""
    scenes: list[str] | None = None
    tracker: str = "mlflow"
    tracking_uri: str | None = None
    experiment: str = "sray-stability"
    device: str | None = None

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> StabilityJob:
        """The job of parsed CLI arguments; ValueError names the flag and the fix."""
        paths = {field: getattr(args, field) for field in MODEL_FLAGS}
        for field, path in paths.items():
            if path is not None and not Path(path).exists():
                raise ValueError(f"{MODEL_FLAGS[field]} {path}: no such folder; pass a checkpoint folder written by "
                                 "`sray train` (…/checkpoints/step_XXXXXXXXX) or, for --segmenter, a folder written "
                                 "by `sray bench segmenter`")
        if paths["checkpoint"] is None and (args.data is not None or any(paths.values())):
            raise ValueError("--data, --checkpoint-no-cra and --segmenter need --checkpoint (the S-Ray model the rows "
                             "are built from); leave them all out to let the preset build its world and pretrain "
                             "every model")
        if args.data is not None and not (Path(args.data) / "manifest.json").exists():
            raise ValueError(f"--data {args.data}: no manifest.json there; pass a folder written by `sray data shard`")
        given = None if paths["checkpoint"] is None else SuiteModels(
            **{field: None if path is None else Path(path).resolve() for field, path in paths.items()})
        preset = PRESETS[args.preset]
        out = args.out or Path("outputs/stability") / preset.name
        return cls(preset=preset, axes=list(args.axes), methods=list(dict.fromkeys(args.methods)),
                   modes=list(dict.fromkeys(args.modes)), out=Path(out).resolve(), doc=args.doc, given=given,
                   data=None if args.data is None else Path(args.data).resolve(), scenes=args.scenes,
                   tracker=args.tracker, tracking_uri=args.tracking_uri, experiment=args.experiment,
                   device=args.device)

    @property
    def store(self) -> str:
        """The tracker's store (default: a SQLite store in the output folder)."""
        return self.tracking_uri or f"sqlite:///{self.out / 'mlflow.db'}"


def resolve_models(job: StabilityJob) -> tuple[Path, SuiteModels]:
    """(shards, models): those given (shards: the checkpoint's by default), or the preset's world, pretrained."""
    if job.given is None:
        job.out.mkdir(parents=True, exist_ok=True)
        shards = world_shards(job.preset, job.out)
        return shards, world_models(job.preset, shards, job.out, job.store)
    if job.data is not None:
        return job.data, job.given
    _, cfg = model_from_checkpoint(job.given.checkpoint)
    shards = Path(cfg.data.shards).resolve()
    if not (shards / "manifest.json").exists():
        raise ValueError(f"--checkpoint {job.given.checkpoint}: its training shards {cfg.data.shards} (data.shards) "
                         "hold no manifest.json here; pass --data SHARDS with the unseen test scenes")
    return shards, job.given


def _label_space(models: SuiteModels) -> tuple[SRayConfig, SRayConfig | None]:
    """The model configs of the S-Ray and no-CRA checkpoints (None: none); ValueError when their labels differ."""
    _, cfg = model_from_checkpoint(models.checkpoint)
    if models.checkpoint_no_cra is None:
        return cfg.model, None
    _, other = model_from_checkpoint(models.checkpoint_no_cra)
    if (other.model.n_classes, other.model.ignore_id) != (cfg.model.n_classes, cfg.model.ignore_id):
        raise ValueError(f"--checkpoint-no-cra {models.checkpoint_no_cra} predicts {other.model.n_classes} classes, "
                         f"--checkpoint {models.checkpoint} {cfg.model.n_classes}; pretrain both on the same data")
    return cfg.model, other.model


def check_rows(rows: list[Row], models: SuiteModels, preset: Preset, n_classes: int, where: Path) -> None:
    """Build each zero-shot row's model (CPU) and trained row's fleet settings now: ValueError naming a bad flag."""
    for row in rows:
        if not row.trained:
            model = get_method(row.method).eval_model(row.request(models, "cpu"))
            if model.n_classes != n_classes:
                raise ValueError(f"{where}: the scenes have {n_classes} classes, {model.subject} of row {row.name!r} "
                                 f"predicts {model.n_classes}; give models of the scenes' label space")
    cfg = scene_settings(preset, models.segmenter)
    for method in dict.fromkeys(r.method for r in rows if r.trained):
        check = get_method(method).checked_config
        cfg = check(cfg) if check is not None else cfg


def prepare(job: StabilityJob) -> tuple[SuiteInputs, list[Row]]:
    """The suite's inputs and rows, every model found and checked (pretrained first when none is given)."""
    shards, models = resolve_models(job)
    names, metas = select_scenes(shards, job.scenes)
    checkpoint, no_cra = _label_space(models)
    n_classes = checkpoint.n_classes
    scene_classes = {len(m["class_names"]) for m in metas.values()}
    if scene_classes != {n_classes}:
        raise ValueError(f"{shards / 'manifest.json'}: scenes have {sorted(scene_classes)} classes, the checkpoint "
                         f"predicts {n_classes}; score it on data of its own label space")
    rows = suite_rows(job.methods, job.modes, checkpoint, no_cra)
    rows = [r for r in rows if any(AXES[a].applies(r) for a in job.axes)]
    if not rows:
        raise ValueError(f"--axes {job.axes} stress none of the rows of --methods {job.methods} --modes {job.modes}")
    check_rows(rows, models, job.preset, n_classes, shards / "manifest.json")
    device = job.device or ("cuda" if torch.cuda.is_available() else "cpu")
    suite = SuiteInputs(job.preset, str(shards), tuple(names), tuple(rows), models, n_classes, checkpoint.ignore_id,
                        device)
    return suite, rows


def run_job(job: StabilityJob, suite: SuiteInputs, rows: list[Row]) -> dict[str, Any]:
    """Run the suite; ``write_outputs``'s dict plus ``parent_run`` and ``axes`` (those whose points are all stored)."""
    job.out.mkdir(parents=True, exist_ok=True)
    outcomes = run_points(job.out, planned_points(job.preset, job.axes, rows), suite)
    errors = {o.key: o.note for o in outcomes if o.reason == "errored"}
    done = [a for a in AXES if point_records(job.out, job.preset, planned_points(job.preset, [a], rows), errors)]
    records = point_records(job.out, job.preset, planned_points(job.preset, done, rows), errors)
    shards = Path(suite.shards)
    protocols = {r.name: r.protocol(shards, job.preset.n_source, job.preset.eval_stride) for r in rows}
    models = {k: str(v) for k, v in dataclasses.asdict(suite.models).items() if v is not None}
    extra = {"shards": suite.shards, "models": models, "scenes": list(suite.scenes), "methods": job.methods,
             "modes": job.modes}
    shown = [r for r in rows if any(AXES[a].applies(r) for a in done)]
    outputs = write_outputs(records, job.preset, done, shown, protocols, job.out, extra)
    tracker = get_tracker(job.tracker, job.store)
    run_name = f"stability-{job.preset.name}-{job.out.name}"
    outputs["parent_run"] = track(tracker, job.experiment, run_name, outputs, records, done, job.preset)
    outputs["axes"] = done
    return outputs
