"""What the stability suite computes: every (axis, row, level, seed) a run asks for, and the result of a spec (a
method that raises, diverges or outputs non-finite values is ``failed`` there, and the suite goes on).

A point record: ``axis``, ``method`` (the row's name), ``level``, ``seed`` (None: deterministic), ``status``,
``miou`` (%) and ``psnr`` (dB) (None when failed), ``x`` (the chart's x), ``error``, ``key`` and the spec's result.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from sray.platform.common.fault_hook import poisoned_point
from sray.platform.eval.eval_model import EvalModel
from sray.platform.stability.axes import AXES, PointSpec, Preset, point_spec
from sray.platform.stability.rows import Row
from sray.platform.stability.scene_points import SceneTraining, scene_point
from sray.platform.stability.stress_scenes import StressScene
from sray.platform.stability.zero_shot_points import zero_shot_point

Planned = list[tuple[str, Row, Any, int | None]]
"""(axis, row, level, seed) of points (:func:`planned_points`)."""


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
    """The key a point's result is stored under (its spec's, ``_poisoned`` when a fault drill poisons it), its spec,
    and whether it is poisoned."""
    spec = point_spec(axis, row, level, 0 if seed is None else seed, preset)
    poison = poisoned_point(row.name, axis, level)
    return f"{spec.key()}{'_poisoned' if poison else ''}", spec, poison


def point_record(axis: str, row: Row, level: Any, seed: int | None, result: dict[str, Any],
                 key: str) -> dict[str, Any]:
    """The record of one point (module doc) from the result of its spec."""
    return {**result, "axis": axis, "method": row.name, "level": level, "seed": seed,
            "x": _x(axis, level, result) if result["status"] == "ok" else None, "key": key}
