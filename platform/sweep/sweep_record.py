"""``<sweep folder>/sweep.json``: everything needed to continue a sweep (``sray sweep --resume NAME`` reads it
instead of a spec), written before its first trial."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json

RECORD_FILE = "sweep.json"
FORMAT = "sray-sweep"


@dataclass
class SweepRecord:
    """A sweep's stored description and progress."""

    name: str
    options: dict[str, Any]
    """``SweepOptions`` as a dict."""
    params: list[str]
    """Each swept field as ``section.field=SPEC``."""
    plan: dict[str, dict[str, Any]]
    """Trial key -> field path -> value."""
    base: dict[str, Any]
    """The trials' common training config (``TrainConfig.to_dict``)."""
    register_as: str
    """Model name the best trial's checkpoint is registered under ('' = not registered)."""
    tracker: str
    """Registry name of the tracker."""
    store: str
    """The tracker's store (MLflow: the tracking URI)."""
    parent_run_id: str = ""
    """Id of the sweep's parent run ('' before it exists)."""
    finished_children: list[str] = field(default_factory=list)
    """Keys of the trials whose child runs have been finished (tags, checkpoint, status)."""
    registered: str = ""
    """Key of the trial registered as the best model ('' = none yet)."""
    format: str = FORMAT


def write_sweep_record(folder: Path, record: SweepRecord) -> Path:
    """Write ``sweep.json`` atomically; returns its path."""
    path = Path(folder) / RECORD_FILE
    atomic_write_json(path, asdict(record))
    return path


def read_sweep_record(folder: Path) -> SweepRecord:
    """The sweep recorded in ``folder``; FileNotFoundError or ValueError naming the file and the fix."""
    path = Path(folder) / RECORD_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing, so there is no sweep {Path(folder).name!r} to resume; check "
                                "--resume NAME and --out")
    raw = json.loads(path.read_text())
    if raw.get("format") != FORMAT:
        raise ValueError(f"{path}: field 'format' is {raw.get('format')!r}, expected {FORMAT!r}")
    return SweepRecord(**raw)
