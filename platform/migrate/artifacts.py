"""``sray migrate PATH``: find the stored artifacts of an earlier sray under PATH and convert them to today's format.

What it converts (format 1: everything sray wrote up to commit 7734061, ``config_v1``):

* a training checkpoint folder (``meta.json`` + ``state.pt``): its config, its model keys (the oldest ones hold the
  training module's ``net.``-prefixed keys), its counters (every one present: those an older sray did not count
  become 0, or NaN = unknown for the wall seconds of a checkpoint past step 0), ``meta.json`` version 2;
* a job's ``config.json`` (``sray train --resume`` reads it);
* a sweep's ``sweep.json``: its base config and the parameters it sweeps (moved paths renamed);
* a fleet's ``fleet.json`` written before trackers had names (its tracker: MLflow);
* a 2D segmenter folder (``segmenter.json`` and an unfinished training's ``training_state.pt``): the removed
  ``encoder_norm`` setting.

Everything is converted in memory first; only when every artifact converts is anything written, each file or
checkpoint folder atomically (``sray.data_tools.atomic``), so a refusal leaves PATH as it was. An artifact already
in today's format is left alone.
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from sray.data_tools.atomic import atomic_write_bytes, atomic_write_json, replace_dir
from sray.platform.checkpoints.folders import FORMAT, META_FILE, STATE_FILE, VERSION, check_weights_only_safe
from sray.platform.config.stored_format import VERSION_KEY
from sray.platform.config.train_config import CONFIG_FILE, TrainConfig
from sray.platform.finetune.fleet import FLEET_FILE
from sray.platform.migrate.config_v1 import MigrationRefused, removed_value, today_path, train_config_v2
from sray.platform.sweep.prepare import FORMAT as SWEEP_FORMAT, RECORD_FILE as SWEEP_FILE

SEGMENTER_FILE, SEGMENTER_STATE = "segmenter.json", "training_state.pt"
"""A 2D segmenter folder's config and an unfinished training's state (``sray.platform.eval.segmenter*``)."""
LEGACY_PREFIX = "net."
"""Format 1's oldest checkpoints hold the training module's keys: ``net.`` + the bare model's."""


@dataclass
class Conversion:
    """One artifact's conversion, computed and checked, not yet written."""

    path: Path
    """The file or checkpoint folder it replaces."""
    what: str
    """What it is, for the report line."""
    write: Callable[[], None]
    """Writes the converted artifact in place, atomically."""


def _json(path: Path) -> Any:
    """The JSON of ``path``; MigrationRefused when it is not JSON."""
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise MigrationRefused(f"{path}: not a JSON file sray wrote ({e})") from None


def _checked(d: dict[str, Any], where: Path) -> dict[str, Any]:
    """``d`` converted to format 2 and proven to load as today's ``TrainConfig``."""
    out = train_config_v2(d, str(where))
    try:
        TrainConfig.from_dict(out)
    except (TypeError, ValueError) as e:
        raise MigrationRefused(f"{where}: not a training config this sray understands ({e})") from None
    return out


def _state_bytes(state: dict[str, Any]) -> bytes:
    check_weights_only_safe(state)
    buffer = io.BytesIO()
    torch.save(state, buffer)
    return buffer.getvalue()


def checkpoint(folder: Path) -> Conversion | None:
    """The conversion of checkpoint folder ``folder`` (None when already today's)."""
    meta = _json(folder / META_FILE)
    if meta.get("format") != FORMAT or meta.get("version") not in (1, VERSION):
        raise MigrationRefused(f"{folder / META_FILE}: format {meta.get('format')!r} version {meta.get('version')!r} "
                               f"is not an sray checkpoint this sray understands")
    if meta["version"] == VERSION:
        return None
    state = torch.load(folder / STATE_FILE, map_location="cpu", weights_only=True)
    state["config"] = _checked(state["config"], folder / STATE_FILE)
    if state["model"] and all(k.startswith(LEGACY_PREFIX) for k in state["model"]):
        state["model"] = {k.removeprefix(LEGACY_PREFIX): v for k, v in state["model"].items()}
    state.setdefault("best_metric", None)
    counters = state.setdefault("counters", {})
    counters.pop("ray_phase_cpu_seconds", None)  # kept only for the removed optim.lr_decay_start
    for name in ("skipped_steps", "cpu_seconds", "peak_memory_mb"):
        counters.setdefault(name, 0.0 if name != "skipped_steps" else 0)
    counters.setdefault("wall_seconds", 0.0 if int(state["step"]) == 0 else math.nan)
    data, new_meta = _state_bytes(state), {**meta, "version": VERSION}

    def write() -> None:
        tag = f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
        ready = folder.with_name(f".migrate-{folder.name}-{tag}")
        shutil.copytree(folder, ready)
        try:
            (ready / STATE_FILE).write_bytes(data)
            (ready / META_FILE).write_text(json.dumps(new_meta, indent=1) + "\n")
            replace_dir(ready, folder, folder.with_name(f".old-{folder.name}-{tag}"))
        except BaseException:
            shutil.rmtree(ready, ignore_errors=True)
            raise
    return Conversion(folder, "checkpoint", write)


def job_config(path: Path) -> Conversion | None:
    """The conversion of a job's ``config.json`` (None when already today's or not a training config)."""
    d = _json(path)
    if not isinstance(d, dict) or not {"model", "data", "run"} <= set(d) or VERSION_KEY in d:
        return None
    out = _checked(d, path)
    return Conversion(path, "job config", lambda: atomic_write_json(path, out))


def sweep_record(path: Path) -> Conversion | None:
    """The conversion of a sweep's ``sweep.json`` (None when already today's)."""
    record = _json(path)
    if record.get("format") != SWEEP_FORMAT:
        raise MigrationRefused(f"{path}: format {record.get('format')!r} is not an sray sweep record")
    if VERSION_KEY in record["base"]:
        return None
    record["base"] = _checked(record["base"], path)
    plan = {}
    for key, point in record["plan"].items():
        for field, value in point.items():
            if today_path(field) is None:
                removed_value(field, value, f"{path}: trial {key}")
        plan[key] = {today_path(field): value for field, value in point.items() if today_path(field) is not None}
    params = [f"{today_path(field)}={spec}" for field, _, spec in (p.partition("=") for p in record["params"])
              if today_path(field) is not None]
    record["plan"], record["params"] = plan, params
    return Conversion(path, "sweep record", lambda: atomic_write_json(path, record))


def segmenter(folder: Path) -> list[Conversion]:
    """The conversions of a 2D segmenter folder: its ``segmenter.json`` and an unfinished training's state (the
    removed ``encoder_norm`` setting, dropped where it is the instance norm every segmenter now has)."""
    out = []
    path = folder / SEGMENTER_FILE
    stored = _json(path)
    if "encoder_norm" in stored.get("config", {}):
        removed_value("model.encoder_norm", stored["config"].pop("encoder_norm"), str(path))
        stored.get("training", {}).pop("encoder_norm", None)
        out.append(Conversion(path, "segmenter config", lambda: atomic_write_json(path, stored)))
    state_path = folder / SEGMENTER_STATE
    if state_path.is_file():
        state = torch.load(state_path, map_location="cpu", weights_only=True)
        if "encoder_norm" in state.get("settings", {}):
            removed_value("model.encoder_norm", state["settings"].pop("encoder_norm"), str(state_path))
            data = _state_bytes(state)
            out.append(Conversion(state_path, "segmenter training state",
                                  lambda: atomic_write_bytes(state_path, data)))
    return out


def fleet_record(path: Path) -> Conversion | None:
    """The conversion of a fleet's ``fleet.json`` written before trackers had names (its runs are MLflow's)."""
    record = _json(path)
    if record.get("format") != "sray-fleet":
        raise MigrationRefused(f"{path}: format {record.get('format')!r} is not an sray fleet record")
    if "tracker" in record:
        return None
    record["tracker"] = "mlflow"
    return Conversion(path, "fleet record", lambda: atomic_write_json(path, record))


def find_conversions(root: Path) -> list[Conversion]:
    """Every conversion under ``root`` (a file or a folder, searched recursively); MigrationRefused (one line) for
    the first artifact that cannot be converted, or when ``root`` holds nothing ``sray migrate`` knows."""
    root = Path(root)
    if not root.exists():
        raise MigrationRefused(f"{root}: no such file or folder")
    if root.is_file():
        folders, files = [], [root]
        if root.name in (STATE_FILE, META_FILE, SEGMENTER_STATE):
            folders, files = [root.parent], []
    else:
        folders = [root, *(p for p in sorted(root.rglob("*")) if p.is_dir() and not p.name.startswith("."))]
        files = []
    found, known = [], False
    for folder in folders:
        if (folder / META_FILE).is_file() and (folder / STATE_FILE).is_file():
            known = True
            found.append(checkpoint(folder))
        if (folder / SEGMENTER_FILE).is_file():
            known = True
            found += segmenter(folder)
        files += [folder / name for name in (CONFIG_FILE, SWEEP_FILE, FLEET_FILE) if (folder / name).is_file()]
    for file in files:
        if file.name == SWEEP_FILE:
            known = True
            found.append(sweep_record(file))
        elif file.name == FLEET_FILE:
            known = True
            found.append(fleet_record(file))
        elif file.name == CONFIG_FILE:
            conversion = job_config(file)
            known = known or conversion is not None or VERSION_KEY in _json(file)
            found.append(conversion)
        elif file.name == SEGMENTER_FILE:
            known = True
            found += segmenter(file.parent)
        else:
            raise MigrationRefused(f"{file}: not an artifact sray migrate understands (a checkpoint folder, a job's "
                                   f"{CONFIG_FILE}, a sweep's {SWEEP_FILE}, a fleet's {FLEET_FILE} or a segmenter "
                                   "folder)")
    if not known:
        raise MigrationRefused(f"{root}: holds no sray artifact (a checkpoint folder, a job's {CONFIG_FILE}, a sweep's "
                               f"{SWEEP_FILE} or a segmenter folder)")
    return [c for c in found if c is not None]
