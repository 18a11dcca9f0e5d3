"""``sray migrate PATH``: convert the stored artifacts of an earlier sray under PATH to today's format. Training
configs (``config_formats``) in checkpoints, jobs' ``config.json`` and sweeps' ``sweep.json`` (swept parameters too);
a version-1 checkpoint's (up to 7734061) model keys (the oldest ``net.``-prefixed) and counters (0, or NaN = unknown
for the wall seconds past step 0); a ``fleet.json`` without a tracker name gets MLflow; Semantic-NeRF artifacts and
2D segmenters lose removed settings. Nothing is written (atomically) until everything converts, so a refusal leaves
PATH as it was; an artifact already in today's format is left alone."""

from __future__ import annotations

import io
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import torch
from safetensors import safe_open
from safetensors.torch import save

from sray.data_tools.atomic import atomic_write_bytes, atomic_write_json
from sray.platform.checkpoints.folders import FORMAT, META_FILE, STATE_FILE, VERSION, check_weights_only_safe
from sray.platform.config.stored_format import CONFIG_VERSION, VERSION_KEY
from sray.platform.config.train_config import CONFIG_FILE, TrainConfig
from sray.platform.finetune.fleet import FLEET_FILE
from sray.platform.finetune.methods.semantic_nerf_method import METHOD as SEMANTIC_NERF
from sray.platform.migrate.config_formats import (MigrationRefused, drop_removed, refuse_unless_noop, today_path,
                                                   train_config_today)
from sray.platform.sweep.prepare import FORMAT as SWEEP_FORMAT, RECORD_FILE as SWEEP_FILE

SEGMENTER_FILE, SEGMENTER_STATE = "segmenter.json", "training_state.pt"
"""A 2D segmenter folder's config and an unfinished training's state (``sray.platform.eval.segmenter*``)."""
SEGMENTER_REMOVED = {"encoder_norm": ("instance", "7734061")}
NERF_REMOVED = {"density_activation": ("softplus", "7966ddf")}
"""Removed settings of a segmenter's and a Semantic-NeRF's config, as ``config_formats.REMOVED_FIELDS``."""


class Conversion(NamedTuple):
    """One artifact's conversion, computed and checked, not yet written: the file or checkpoint folder it replaces,
    what it is (for the report line) and the function that writes it in place, atomically."""

    path: Path
    what: str
    write: Callable[[], None]


def _json(path: Path) -> Any:
    """The JSON of ``path``; MigrationRefused when it is not JSON."""
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise MigrationRefused(f"{path}: not a JSON file sray wrote ({e})") from None


def _checked(d: dict[str, Any], where: Path) -> dict[str, Any]:
    """``d`` converted to today's format and proven to load as today's ``TrainConfig``."""
    out = train_config_today(d, str(where))
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


def checkpoint(folder: Path) -> list[Conversion] | None:
    """The conversion of checkpoint folder ``folder`` (none when already today's; None: not a checkpoint folder)."""
    if not (folder / META_FILE).is_file() or not (folder / STATE_FILE).is_file():
        return None
    meta = _json(folder / META_FILE)
    if meta.get("format") != FORMAT or meta.get("version") not in (1, VERSION):
        raise MigrationRefused(f"{folder / META_FILE}: format {meta.get('format')!r} version {meta.get('version')!r} "
                               f"is not an sray checkpoint this sray understands")
    state = torch.load(folder / STATE_FILE, map_location="cpu", weights_only=True, mmap=True)
    if meta["version"] == VERSION and state["config"].get(VERSION_KEY) == CONFIG_VERSION:
        return []
    state["config"] = _checked(state["config"], folder / STATE_FILE)
    if meta["version"] == 1:
        if state["model"] and all(k.startswith("net.") for k in state["model"]):
            state["model"] = {k.removeprefix("net."): v for k, v in state["model"].items()}
        state.setdefault("best_metric", None)
        counters = state.setdefault("counters", {})
        counters.pop("ray_phase_cpu_seconds", None)  # kept only for the removed optim.lr_decay_start
        for name, value in {"skipped_steps": 0, "cpu_seconds": 0.0, "peak_memory_mb": 0.0,
                            "wall_seconds": 0.0 if int(state["step"]) == 0 else math.nan}.items():
            counters.setdefault(name, value)
    data, new_meta = _state_bytes(state), {**meta, "version": VERSION}

    def write() -> None:  # the state first: one still marked version 1 is converted again, to the same
        atomic_write_bytes(folder / STATE_FILE, data)
        atomic_write_json(folder / META_FILE, new_meta)
    return [Conversion(folder, "checkpoint", write)]


def job_config(path: Path) -> list[Conversion] | None:
    """The conversion of a job's ``config.json`` (none when already today's; None when not a training config)."""
    d = _json(path)
    if not isinstance(d, dict) or not {"model", "data", "run"} <= set(d):
        return None
    if d.get(VERSION_KEY) == CONFIG_VERSION:
        return []
    out = _checked(d, path)
    return [Conversion(path, "job config", lambda: atomic_write_json(path, out))]


def sweep_record(path: Path) -> list[Conversion]:
    """The conversion of a sweep's ``sweep.json`` (none when already today's)."""
    record = _json(path)
    if record.get("format") != SWEEP_FORMAT:
        raise MigrationRefused(f"{path}: format {record.get('format')!r} is not an sray sweep record")
    if record["base"].get(VERSION_KEY) == CONFIG_VERSION:
        return []
    record["base"] = _checked(record["base"], path)
    for key, point in record["plan"].items():
        for field in [f for f in point if today_path(f) is None]:
            refuse_unless_noop(field, point.pop(field), f"{path}: trial {key}")
        record["plan"][key] = {today_path(field): value for field, value in point.items()}
    record["params"] = [f"{today_path(field)}={spec}" for field, _, spec in (p.partition("=") for p in record["params"])
                        if today_path(field) is not None]
    return [Conversion(path, "sweep record", lambda: atomic_write_json(path, record))]


def segmenter(folder: Path) -> list[Conversion] | None:
    """The conversions of a 2D segmenter folder's ``segmenter.json`` and training state (None: not one)."""
    path, state_path, out = folder / SEGMENTER_FILE, folder / SEGMENTER_STATE, []
    if not path.is_file():
        return None
    stored = _json(path)
    if "encoder_norm" in stored.get("config", {}):
        drop_removed(stored["config"], SEGMENTER_REMOVED, str(path))
        stored.get("training", {}).pop("encoder_norm", None)
        out.append(Conversion(path, "segmenter config", lambda: atomic_write_json(path, stored)))
    state = torch.load(state_path, map_location="cpu", weights_only=True) if state_path.is_file() else {}
    if "encoder_norm" in state.get("settings", {}):
        drop_removed(state["settings"], SEGMENTER_REMOVED, str(state_path))
        data = _state_bytes(state)
        out.append(Conversion(state_path, "segmenter training state", lambda: atomic_write_bytes(state_path, data)))
    return out


def semantic_nerf(path: Path) -> list[Conversion]:
    """The conversion of a Semantic-NeRF scene artifact (none when already today's)."""
    with safe_open(str(path), framework="pt") as f:
        metadata = dict(f.metadata() or {})
        if metadata.get("method") != SEMANTIC_NERF.name:
            raise MigrationRefused(f"{path}: method {metadata.get('method')!r} is not a Semantic-NeRF scene artifact")
        config = json.loads(metadata["config"])
        if not NERF_REMOVED.keys() & config.keys():
            return []
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    drop_removed(config, NERF_REMOVED, str(path))
    data = save(tensors, metadata=metadata | {"config": json.dumps(config)})
    return [Conversion(path, "Semantic-NeRF artifact", lambda: atomic_write_bytes(path, data))]


def fleet_record(path: Path) -> list[Conversion]:
    """The conversion of a fleet's ``fleet.json`` written before trackers had names (its runs are MLflow's)."""
    record = _json(path)
    if record.get("format") != "sray-fleet":
        raise MigrationRefused(f"{path}: format {record.get('format')!r} is not an sray fleet record")
    if "tracker" in record:
        return []
    record["tracker"] = "mlflow"
    return [Conversion(path, "fleet record", lambda: atomic_write_json(path, record))]


FILES: dict[str, Callable[[Path], list[Conversion] | None]] = {
    CONFIG_FILE: job_config, SWEEP_FILE: sweep_record, FLEET_FILE: fleet_record,
    SEMANTIC_NERF.artifact_file: semantic_nerf}
"""Artifact file name -> its conversions (None: a file of that name that sray did not write)."""
FOLDERS = (checkpoint, segmenter)
"""The conversions of an artifact folder (None: a folder of another kind)."""
KINDS = (f"a checkpoint folder, a job's {CONFIG_FILE}, a sweep's {SWEEP_FILE}, a fleet's {FLEET_FILE}, a "
         f"{SEMANTIC_NERF.artifact_file} or a segmenter folder")


def find_conversions(root: Path) -> list[Conversion]:
    """Every conversion under ``root`` (a file or a folder, searched recursively); MigrationRefused (one line) for
    the first artifact that cannot be converted, or when ``root`` holds nothing ``sray migrate`` knows."""
    root = Path(root)
    if not root.exists():
        raise MigrationRefused(f"{root}: no such file or folder")
    if root.is_file() and root.name in FILES:
        found = [FILES[root.name](root)]
    elif root.is_file() and root.name in (STATE_FILE, META_FILE, SEGMENTER_FILE, SEGMENTER_STATE):
        found = [kind(root.parent) for kind in FOLDERS]
    elif root.is_file():
        raise MigrationRefused(f"{root}: not an artifact sray migrate understands ({KINDS})")
    else:
        folders = [root, *(p for p in sorted(root.rglob("*")) if p.is_dir() and not p.name.startswith("."))]
        found = [kind(folder) for folder in folders for kind in FOLDERS]
        found += [kind(f / name) for f in folders for name, kind in FILES.items() if (f / name).is_file()]
    if all(conversions is None for conversions in found):
        raise MigrationRefused(f"{root}: holds no sray artifact ({KINDS})")
    return [c for conversions in found if conversions for c in conversions]
