"""A study's per-room finetune and ceiling evaluations (docs/sweeps.md, "Studies").

```yaml
evaluations: [zero_shot, held_out, validation, fleet, ceilings]
fleet: {cpu_seconds: 60, rooms: 4}     # S-Ray finetuned per test room: cpu_seconds and/or seconds (wall), steps, rooms
ceilings: {scenes: test, views: 2}     # optional: scenes (test or held_out), views, probe_steps, probe_views
```

``fleet`` finetunes the trial's checkpoint on each of the first ``rooms`` ``zero_shot`` rooms with the S-Ray method,
as ``sray finetune-fleet`` does (:func:`~sray.platform.finetune.fleet.run_fleet`: one tracked task per room, a
re-launch skips finished rooms), stopping at the first limit of its budget or the fleet's early stop, and stores the
held-out mIoU after it. ``ceilings`` scores the ceiling rows of ``sray lab ceilings`` (:mod:`sray.lab.ceilings.measure`,
no segmenter: rows a, s, d, e, e-rand) on the arm's own world, whose training rooms fit the probes: its unseen test
rooms (``scenes: test``) or the held-out views of its first ``held_out_rooms`` training rooms
(``scenes: held_out``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sray.lab.ceilings.measure import measure_ceilings
from sray.lab.ceilings.report import REPORT_FILE
from sray.lab.studies.splits import Fail
from sray.model.fast_render import FastRender
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.config.fleet_config import FleetConfig
from sray.platform.eval.zero_shot import write_json_atomic
from sray.platform.finetune.fleet import run_fleet
from sray.platform.finetune.fleet_report import summary_metrics
from sray.platform.finetune.methods.sray_method import METHOD as SRAY

CEILING_ROOMS = {"test": "its unseen test rooms", "held_out": "held-out views of its first training rooms"}
"""Values of ``ceilings.scenes``: which rooms of the arm's world the ceilings score."""


@dataclass(frozen=True)
class FleetEval:
    """Settings of the ``fleet`` evaluation (0 / None: no such limit)."""

    cpu_seconds: float = 0.0
    """Training CPU seconds per room (``finetune.max_cpu_seconds``)."""
    seconds: float = 0.0
    """Training wall seconds per room (``finetune.max_seconds``)."""
    steps: int | None = None
    """Most steps per room (``finetune.max_steps``; None: the fleet's default)."""
    rooms: int | None = None
    """The first ``rooms`` zero-shot rooms (None: every one)."""

    def describe(self) -> str:
        """``60 CPU s per room``, with the wall and step limits when set."""
        limits = [f"{self.cpu_seconds:g} CPU s"] if self.cpu_seconds else []
        limits += [f"{self.seconds:g} s"] if self.seconds else []
        return " or ".join(limits + ([f"{self.steps} steps"] if self.steps else [])) + " per room"

    def config(self, experiment: str, n_source: int) -> FleetConfig:
        """The fleet's configuration: ``sray finetune-fleet``'s defaults with this budget, the held-out views scored
        from ``n_source`` sources (the study's), tracked in ``experiment``."""
        cfg = FleetConfig(experiment=experiment)
        cfg.finetune.max_cpu_seconds, cfg.finetune.max_seconds = self.cpu_seconds, self.seconds
        cfg.finetune.held_out.n_source = n_source
        if self.steps:
            cfg.finetune.max_steps = self.steps
        return cfg


@dataclass(frozen=True)
class CeilingsEval:
    """Settings of the ``ceilings`` evaluation (``sray lab ceilings``' flags of the same names)."""

    scenes: str = "test"
    """One of :data:`CEILING_ROOMS`."""
    views: int = 0
    """First query views per room (0: all)."""
    probe_steps: int = 300
    probe_views: int = 64


def _block(path: Path, name: str, raw: Any, evaluations: list[str], keys: tuple[str, ...], fail: Fail) -> dict | None:
    """The study file's ``name`` mapping (None when absent), its keys among ``keys``; listed in ``evaluations``."""
    if raw is None:
        return None
    if name not in evaluations:
        raise fail(path, name, "settings of an evaluation the study does not list",
                   f"add {name} to evaluations or drop the key")
    if not isinstance(raw, dict):
        raise fail(path, name, f"{raw!r} is not a mapping", f"write {name}: {{{keys[0]}: ...}}")
    unknown = sorted(set(raw) - set(keys))
    if unknown:
        raise fail(path, f"{name}.{unknown[0]}", "not a setting of it", f"{name} takes {', '.join(keys)}")
    return raw


def _number(path: Path, where: str, value: Any, fail: Fail, integer: bool) -> Any:
    """``value`` when it is a positive number (an integer >= 1 where ``integer``)."""
    kinds = int if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kinds) or not value > 0 or not math.isfinite(value):
        raise fail(path, where, f"{value!r} is not a positive {'integer' if integer else 'number'}",
                   f"write e.g. {4 if integer else 60}")
    return value


def parse_fleet(path: Path, raw: Any, evaluations: list[str], fail: Fail) -> FleetEval | None:
    """The ``fleet`` settings of a study file (None when ``fleet`` is not an evaluation)."""
    block = _block(path, "fleet", raw, evaluations, ("cpu_seconds", "seconds", "steps", "rooms"), fail)
    if "fleet" not in evaluations:
        return None
    if not block or not {"cpu_seconds", "seconds"} & set(block):
        raise fail(path, "fleet", "a per-room finetune needs a time budget", "give fleet: {cpu_seconds: 60} (training "
                   "CPU s per room; or seconds: wall), with steps and rooms if wanted")
    values = {k: _number(path, f"fleet.{k}", v, fail, k in ("steps", "rooms")) for k, v in block.items()}
    return FleetEval(float(values.get("cpu_seconds", 0.0)), float(values.get("seconds", 0.0)), values.get("steps"),
                     values.get("rooms"))


def parse_ceilings(path: Path, raw: Any, evaluations: list[str], fail: Fail) -> CeilingsEval | None:
    """The ``ceilings`` settings of a study file (None when ``ceilings`` is not an evaluation)."""
    block = _block(path, "ceilings", raw, evaluations, ("scenes", "views", "probe_steps", "probe_views"), fail) or {}
    if "ceilings" not in evaluations:
        return None
    scenes = block.get("scenes", "test")
    if scenes not in CEILING_ROOMS:
        raise fail(path, "ceilings.scenes", f"{scenes!r} is not a room set", f"write one of {', '.join(CEILING_ROOMS)}")
    return CeilingsEval(scenes, **{k: _number(path, f"ceilings.{k}", v, fail, True) for k, v in block.items()
                                   if k != "scenes"})


def _pct(share: float | None) -> float | None:
    """A share (0-1) as percent with two decimals; None (or NaN: nothing measured) stays None."""
    return None if share is None or math.isnan(share) else round(100 * share, 2)


def fleet_blocks(results: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per method of a fleet's ``results`` (``run_fleet``'s result dicts): its finished rooms' mean held-out mIoU
    before and after the finetune (percent), the rooms, their mean training seconds and steps, how they stopped and the
    held-out protocol."""
    summary = summary_metrics(results)
    blocks = {}
    for method in dict.fromkeys(r["method"] for r in results):
        done = [r for r in results if r["method"] == method and r["status"] == "finished"]
        blocks[method] = {"miou": _pct(summary[f"{method}/miou_after_mean"]),
                          "miou_before": _pct(summary[f"{method}/miou_before_mean"]),
                          "rooms": [r["scene"] for r in done],
                          "train_seconds": None if not done else round(summary[f"{method}/wall_s_mean"], 1),
                          "steps": None if not done else round(summary[f"{method}/steps_used_mean"], 1),
                          "stopped_by": sorted({r["stop_reason"] for r in done}),
                          "protocol": EvalProtocol.from_json(done[0]["protocol"]).describe() if done else None}
    return blocks


def fleet_metrics(settings: FleetEval, checkpoint: Path, shards: Path, scenes: list[str], out: Path,
                  tracking_uri: str, experiment: str, n_source: int) -> dict[str, Any]:
    """Finetune ``checkpoint`` with S-Ray on the first ``settings.rooms`` of ``scenes`` (a fleet in folder ``out``,
    held-out views scored from ``n_source`` sources); the result's ``fleet`` block: ``{"sray": {... fleet_blocks'
    fields, "budget"}}``. RuntimeError when a room failed (a rerun of the trial runs only the failed rooms)."""
    results = run_fleet(settings.config(experiment, n_source), checkpoint, shards, scenes[:settings.rooms], out,
                        tracking_uri, [SRAY.name])
    failed = [r for r in results if r["status"] != "finished"]
    if failed:
        raise RuntimeError(f"{out}: the finetune of room {failed[0]['scene']} failed ({failed[0]['error']}); run the "
                           "study again to retry it")
    return {SRAY.name: fleet_blocks(results)[SRAY.name] | {"budget": settings.describe()}}


def ceilings_metrics(settings: CeilingsEval, checkpoint: Path, shards: Path, held_out_rooms: int, n_source: int,
                     render: FastRender | None, out: Path) -> dict[str, Any]:
    """Score the ceiling rows of ``checkpoint`` on ``shards`` (the arm's world), store the full report as
    ``out/ceilings.json`` and return the result's ``ceilings`` block: per row its title, whether it is an oracle and
    its mIoU, total accuracy, coverage and accuracy on covered pixels (percent)."""
    report = measure_ceilings(checkpoint, shards, n_source=n_source, views_per_scene=settings.views,
                              probe_steps=settings.probe_steps, probe_views=settings.probe_views, render=render,
                              held_out=held_out_rooms if settings.scenes == "held_out" else 0, progress=False)
    write_json_atomic(report, Path(out) / REPORT_FILE)
    rows = {r["key"]: {"title": r["title"], "oracle": r["oracle"],
                       **{k: _pct(r[k]) for k in ("miou", "total_acc", "coverage", "acc_on_covered")}}
            for r in report["rows"]}
    protocol = (f"{report['n_source']} fixed sources ({report['source_rule']}); S-Ray's render: {report['render']}; "
                f"probes: {settings.probe_steps} steps on {settings.probe_views} views")
    return {"rows": rows, "scenes": settings.scenes, "rooms": len(report["scenes"]),
            "views": report["rows"][0]["views"], "protocol": protocol}
