"""What the stability suite computes: every (axis, method, level, seed) a run asks for, and one point's result.

Points that show a method the same input share one :class:`~sray.platform.stability.point_spec.PointSpec`,
computed once: :func:`point_key` names it (the spec's key), and the suite's study
(:mod:`sray.platform.stability.points_study`) runs one trial per key on the study engine. A method that
raises, diverges or outputs non-finite values at a point is recorded there as ``failed`` with a one-line
reason (:func:`compute_spec` never raises), and the suite goes on.

A point record (what :mod:`sray.platform.stability.summary` reads): ``axis``, ``method``, ``level``,
``seed`` (None for a deterministic point, computed once), ``status``, ``miou`` and ``psnr`` (dataset-
level mIoU in %, PSNR in dB; None when failed), ``x`` (the chart's x: the level; the measured unseen
fraction on ``unseen_rays``; None on the categorical ``precision``), ``error``, ``key`` and the
spec's result (non-finite rays, fp32 agreement, unseen fraction, steps, per-scene scores).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import nn

from sray.platform.common.fault_hook import poisoned_point
from sray.platform.stability.axes import AXES, SOURCE_METHODS
from sray.platform.stability.nerf_points import nerf_point
from sray.platform.stability.point_spec import PointSpec, point_spec
from sray.platform.stability.presets import Preset
from sray.platform.stability.sray_points import sray_point
from sray.platform.stability.stress_scenes import StressScene


@dataclass
class Suite:
    """What the suite stresses, and with what."""

    preset: Preset
    scenes: list[StressScene]
    nets: dict[str, nn.Module]
    """S-Ray method name -> its pretrained network (in eval mode, on ``device``)."""
    n_classes: int
    ignore_id: int
    device: torch.device = field(default_factory=lambda: torch.device("cpu"))


def planned_points(preset: Preset, axes: list[str], methods: list[str]) -> list[tuple[str, str, Any, int | None]]:
    """(axis, method, level, seed) of every point, deterministic points once (seed None)."""
    planned = []
    for axis in axes:
        for method in [m for m in methods if m in AXES[axis].methods]:
            for level in preset.levels[axis]:
                if point_spec(axis, method, level, 0, preset).seed is None:
                    planned.append((axis, method, level, None))
                else:
                    planned += [(axis, method, level, seed) for seed in range(preset.seeds)]
    return planned


def _x(axis: str, level: Any, result: dict[str, Any]) -> float | None:
    if axis == "unseen_rays":
        return result.get("unseen_fraction")
    return None if isinstance(level, str) else float(level)


def compute_spec(suite: Suite, spec: PointSpec, poison: bool) -> dict[str, Any]:
    """The result of one spec: its scores, or ``status: failed`` with the reason (never raises an Exception)."""
    start = time.perf_counter()
    try:
        if spec.method in SOURCE_METHODS:
            result = sray_point(suite.nets[spec.method], suite.scenes, spec, suite.preset.eval_stride,
                                suite.preset.chunk, suite.device, poison)
        else:
            per_scene = [nerf_point(scene, spec, suite.preset, suite.n_classes, suite.ignore_id, suite.device,
                                    poison) for scene in suite.scenes[:suite.preset.nerf_scenes]]
            result = {"miou": sum(r["miou"] for r in per_scene) / len(per_scene),
                      "psnr": sum(r["psnr"] for r in per_scene) / len(per_scene),
                      "nonfinite_rays": sum(r["nonfinite_rays"] for r in per_scene),
                      "steps": [r["steps"] for r in per_scene], "train_s": [r["train_s"] for r in per_scene],
                      "train_views": per_scene[0]["train_views"],
                      "scenes": {k: v for r in per_scene for k, v in r["scenes"].items()}}
        if result["nonfinite_rays"]:
            result = {**result, "status": "failed", "miou": None, "psnr": None,
                      "error": f"NonFiniteOutput: {result['nonfinite_rays']} rendered rays are not finite"}
        else:
            result = {**result, "status": "ok", "error": None, "miou": 100.0 * result["miou"]}
    except Exception as err:  # noqa: BLE001 - a failing method is a result of the suite, not its end
        first_line = (str(err).splitlines() or [""])[0]
        result = {"status": "failed", "miou": None, "psnr": None, "error": f"{type(err).__name__}: {first_line}"}
    return {**result, "spec": spec.key(), "wall_s": time.perf_counter() - start}


def point_key(preset: Preset, axis: str, method: str, level: Any, seed: int | None) -> tuple[str, PointSpec, bool]:
    """The key a point's result is stored under (its spec's key, ``_poisoned`` added when a fault drill poisons
    it), its spec, and whether it is poisoned."""
    spec = point_spec(axis, method, level, 0 if seed is None else seed, preset)
    poison = poisoned_point(method, axis, level)
    return f"{spec.key()}{'_poisoned' if poison else ''}", spec, poison


def point_record(axis: str, method: str, level: Any, seed: int | None, result: dict[str, Any],
                 key: str) -> dict[str, Any]:
    """The record of one point (see the module docstring) from the result of its spec."""
    return {**result, "axis": axis, "method": method, "level": level, "seed": seed,
            "x": _x(axis, level, result) if result["status"] == "ok" else None, "key": key}
