"""What the stability suite computes: every (axis, row, level, seed) a run asks for, and a spec's result (a zero-shot
row rendered as ``sray eval`` does, a trained row's method trained: ``scene_points``); a method that raises, diverges
or outputs non-finite values is ``failed`` there. A point record: ``axis``, ``method`` (the row), ``level``, ``seed``
(None: deterministic), ``status``, ``miou`` (%), ``psnr`` (dB), ``x`` (the chart's), ``error``, ``key``, the result."""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass
from typing import Any

import torch

from sray.platform.common.fault_hook import poisoned_point
from sray.platform.eval.eval_model import EvalModel
from sray.platform.eval.view_scoring import predict_view, score_scene
from sray.platform.stability.axes import AXES, PointSpec, Preset, point_spec
from sray.platform.stability.rows import Row
from sray.platform.stability.scene_points import SceneTraining, scene_point
from sray.platform.stability.stress_scenes import (OutputWatch, StressScene, choose_sources, perturbed_views,
                                                   source_samples, unseen_fraction)

Planned = list[tuple[str, Row, Any, int | None]]
"""(axis, row, level, seed) of points (:func:`planned_points`)."""
AUTOCAST_DTYPES = {"bf16": torch.bfloat16, "fp16": torch.float16}
"""Inference precisions other than fp32, as autocast dtypes."""


@dataclass
class Suite:
    """What the suite stresses, and with what."""

    preset: Preset
    scenes: list[StressScene]
    rows: dict[str, Row]
    models: dict[str, EvalModel]
    """Zero-shot row name -> its pretrained model (on the run's device)."""
    training: SceneTraining | None
    """What trained rows start from (None: the run has none)."""
    probe: tuple[int, float]
    """Coarse depths per ray and nearest source depth of the unseen fraction (the S-Ray checkpoint's)."""


def planned_points(preset: Preset, axes: list[str], rows: list[Row]) -> Planned:
    """(axis, row, level, seed) of every point, deterministic points once (seed None)."""
    planned = []
    for axis in axes:
        for row in [r for r in rows if AXES[axis].applies(r)]:
            for level in preset.levels[axis]:
                if point_spec(axis, row, level, 0, preset).seed is None:
                    planned.append((axis, row, level, None))
                else:
                    planned += [(axis, row, level, seed) for seed in range(preset.seeds)]
    return planned


def precision_context(precision: str, device: torch.device) -> contextlib.AbstractContextManager:
    """Autocast for ``precision`` (``fp32``: none); ValueError for fp16 off CUDA."""
    if precision == "fp32":
        return contextlib.nullcontext()
    if precision == "fp16" and device.type != "cuda":
        raise ValueError("precision fp16 needs a CUDA device (CPU autocast runs bf16)")
    return torch.autocast(device.type, dtype=AUTOCAST_DTYPES[precision])


def zero_shot_point(model: EvalModel, scenes: list[StressScene], spec: PointSpec, stride: int, chunk: int,
                    probe: tuple[int, float], poison: bool = False) -> dict[str, Any]:
    """Score ``model`` at ``spec`` on ``scenes``: mean mIoU and PSNR, per-scene scores, the unseen fraction
    (``probe``: coarse depths per ray, nearest source depth), non-finite rays and (below fp32) argmax agreement with
    the fp32 render. A perturbation touches the sources the spec picks, drawn once per scene in view order."""
    watch = OutputWatch(poison)
    device = model.device
    per_scene, unseen, agree, total = {}, [], 0, 0
    for scene in scenes:
        views = scene.views
        if spec.perturbation is not None:
            ids = sorted({s for q in scene.test_ids for s in choose_sources(scene, q, spec)})
            views = perturbed_views(scene, ids, *spec.perturbation, spec.seed)
        samples = source_samples(scene, views, spec)
        with precision_context(spec.precision, device):
            scored = score_scene(lambda s: watch.wrap(model.renderer(s)), samples, model.n_classes, model.ignore_id,
                                 stride, chunk, device, model.fast)
        for sample, view in zip(samples, scored.views):
            if spec.precision != "fp32":
                fp32 = predict_view(model.renderer(sample), sample, stride, chunk, device, model.fast)
                agree += int((fp32.pred_label == view.pred_label).sum())
                total += fp32.pred_label.numel()
            unseen.append(unseen_fraction(sample, stride, *probe))
        per_scene[scene.name] = {"miou": scored.scores["miou"], "psnr": scored.scores["psnr"]}
    return {"miou": sum(s["miou"] for s in per_scene.values()) / len(per_scene),
            "psnr": sum(s["psnr"] for s in per_scene.values()) / len(per_scene),
            "unseen_fraction": sum(unseen) / len(unseen), "nonfinite_rays": watch.nonfinite_rays,
            "fp32_agreement": agree / total if total else None, "scenes": per_scene}


def _x(axis: str, level: Any, result: dict[str, Any]) -> float | None:
    if axis == "unseen_rays":
        return result.get("unseen_fraction")
    return None if isinstance(level, str) else float(level)


def _trained(suite: Suite, row: Row, spec: PointSpec, poison: bool) -> dict[str, Any]:
    """A trained row's result: its per-scene trainings, scores averaged over scenes."""
    if suite.training is None:
        raise ValueError(f"row {row.name!r} is trained on the scene, but the suite was built without a checkpoint")
    p = suite.preset
    per_scene = [scene_point(suite.training, row, scene, spec, p.eval_stride, p.chunk, suite.probe, poison)
                 for scene in suite.scenes[:p.trained_scenes]]
    unseen = [r["unseen_fraction"] for r in per_scene if "unseen_fraction" in r]
    return {"miou": sum(r["miou"] for r in per_scene) / len(per_scene),
            "psnr": sum(r["psnr"] for r in per_scene) / len(per_scene),
            "nonfinite_rays": sum(r["nonfinite_rays"] for r in per_scene),
            **({"unseen_fraction": sum(unseen) / len(unseen)} if unseen else {}),
            **{k: [r[k] for r in per_scene] for k in ("steps", "cpu_s", "train_s")},
            "train_views": per_scene[0]["train_views"],
            "scenes": {k: v for r in per_scene for k, v in r["scenes"].items()}}


def compute_spec(suite: Suite, spec: PointSpec, poison: bool) -> dict[str, Any]:
    """The result of one spec: its scores, or ``status: failed`` with the reason (never raises an Exception)."""
    start = time.perf_counter()
    try:
        row = suite.rows[spec.method]
        if row.trained:
            result = _trained(suite, row, spec, poison)
        else:
            result = zero_shot_point(suite.models[row.name], suite.scenes, spec, suite.preset.eval_stride,
                                     suite.preset.chunk, suite.probe, poison)
        if result["nonfinite_rays"]:
            result = {**result, "status": "failed", "miou": None, "psnr": None,
                      "error": f"NonFiniteOutput: {result['nonfinite_rays']} rendered rays are not finite"}
        else:
            result = {**result, "status": "ok", "error": None, "miou": 100.0 * result["miou"]}
    except Exception as err:  # noqa: BLE001 - a failing method is a result of the suite, not its end
        first_line = (str(err).splitlines() or [""])[0]
        result = {"status": "failed", "miou": None, "psnr": None, "error": f"{type(err).__name__}: {first_line}"}
    return {**result, "spec": spec.key(), "wall_s": time.perf_counter() - start}


def point_key(preset: Preset, axis: str, row: Row, level: Any, seed: int | None) -> tuple[str, PointSpec, bool]:
    """(The key a point's result is stored under, ``_poisoned`` when a fault drill poisons it; its spec; poisoned)."""
    spec = point_spec(axis, row, level, 0 if seed is None else seed, preset)
    poison = poisoned_point(row.name, axis, level)
    return f"{spec.key()}{'_poisoned' if poison else ''}", spec, poison


def point_record(axis: str, row: Row, level: Any, seed: int | None, result: dict[str, Any],
                 key: str) -> dict[str, Any]:
    """The record of one point (module doc) from the result of its spec."""
    return {**result, "axis": axis, "method": row.name, "level": level, "seed": seed,
            "x": _x(axis, level, result) if result["status"] == "ok" else None, "key": key}
