"""The stability suite's loop: every (axis, method, level, seed) a run asks for, each a stored result.

A point is computed once per :class:`~sray.platform.stability.point_spec.PointSpec` and stored at
``<out>/points/<spec key>.json`` the moment it finishes (atomically), so an interrupted suite, or one
run axis by axis, computes only what is missing when run again. A method that raises, diverges or
outputs non-finite values at a point is recorded there as ``failed`` with a one-line reason, and the
suite goes on.

A point record (what :mod:`sray.platform.stability.summary` reads): ``axis``, ``method``, ``level``,
``seed`` (None for a deterministic point, computed once), ``status``, ``miou`` and ``psnr`` (dataset-
level mIoU in %, PSNR in dB; None when failed), ``x`` (the chart's x: the level; the measured unseen
fraction on ``unseen_rays``; None on the categorical ``precision``), ``error``, ``key`` and the
spec's result (non-finite rays, fp32 agreement, unseen fraction, steps, per-scene scores).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn

from sray.data_tools.atomic import atomic_write_json
from sray.platform.common.fault_hook import poisoned_point
from sray.platform.stability.axes import AXES, SOURCE_METHODS
from sray.platform.stability.nerf_points import nerf_point
from sray.platform.stability.point_spec import PointSpec, point_spec
from sray.platform.stability.presets import Preset
from sray.platform.stability.sray_points import sray_point
from sray.platform.stability.stress_scenes import StressScene

PRESET_FILE = "preset.json"
"""The preset definition the stored points of a folder were made with."""


@dataclass
class Suite:
    """What one suite run stresses, with what, and where its results go."""

    preset: Preset
    scenes: list[StressScene]
    nets: dict[str, nn.Module]
    """S-Ray method name -> its pretrained network (in eval mode, on ``device``)."""
    n_classes: int
    ignore_id: int
    out_dir: Path
    device: torch.device = field(default_factory=lambda: torch.device("cpu"))

    def points_dir(self) -> Path:
        """Where each spec's result is stored: one folder per preset name."""
        return self.out_dir / "points" / self.preset.name


def check_preset_record(suite: Suite) -> None:
    """Record the preset the stored points were made with (``preset.json``) or refuse a changed one: a stored
    point is only reused under the same levels, budgets and evaluation settings."""
    path = suite.points_dir() / PRESET_FILE
    now = json.loads(json.dumps(dataclasses.asdict(suite.preset)))
    if path.exists():
        if json.loads(path.read_text()) != now:
            raise ValueError(f"{path}: the points in {path.parent} were made with another definition of preset "
                             f"{suite.preset.name!r}; use a new --out, or delete that folder to start again")
        return
    atomic_write_json(path, now)


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


def _stored_at(suite: Suite, axis: str, method: str, level: Any, seed: int | None) -> tuple[PointSpec, bool, Path]:
    """The point's spec, whether a fault drill poisons it, and the file its result is stored in."""
    spec = point_spec(axis, method, level, 0 if seed is None else seed, suite.preset)
    poison = poisoned_point(method, axis, level)
    return spec, poison, suite.points_dir() / f"{spec.key()}{'_poisoned' if poison else ''}.json"


def _record(axis: str, method: str, level: Any, seed: int | None, result: dict[str, Any], path: Path) -> dict[str, Any]:
    return {**result, "axis": axis, "method": method, "level": level, "seed": seed,
            "x": _x(axis, level, result) if result["status"] == "ok" else None, "key": path.stem}


def run_points(suite: Suite, axes: list[str], methods: list[str], progress: bool = True) -> list[dict[str, Any]]:
    """Every planned point's record, computing (and storing) the specs not stored yet."""
    from tqdm import tqdm

    planned = planned_points(suite.preset, axes, methods)
    check_preset_record(suite)
    records, bar = [], tqdm(total=len(planned), desc="stability points", unit="point", disable=not progress)
    for axis, method, level, seed in planned:
        spec, poison, path = _stored_at(suite, axis, method, level, seed)
        if path.exists():
            result = json.loads(path.read_text())
        else:
            bar.set_postfix_str(f"{axis}/{method}/{level}")
            result = compute_spec(suite, spec, poison)
            atomic_write_json(path, result)
        records.append(_record(axis, method, level, seed, result, path))
        bar.update(1)
    bar.close()
    return records


def stored_records(suite: Suite, planned: list[tuple[str, str, Any, int | None]]) -> list[dict[str, Any]] | None:
    """The records of ``planned`` points from storage alone; None when any of them is not stored yet."""
    records = []
    for axis, method, level, seed in planned:
        _, _, path = _stored_at(suite, axis, method, level, seed)
        if not path.exists():
            return None
        records.append(_record(axis, method, level, seed, json.loads(path.read_text()), path))
    return records
