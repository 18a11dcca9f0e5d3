"""Rows of ``sray bench speed-accuracy`` kept per measurement (``--store``) so a long run resumes; the key names all
that was measured (checkpoints, shards, views per scene, setting, methods beside it); CPU seconds compare over runs."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json
from sray.platform.common.machine import describe_machine


def row_key(checkpoint: Path, checkpoint_rgbd: Path | None, shards: Path, views_per_scene: int, setting: Any,
            methods: dict[str, str]) -> dict[str, Any]:
    """What one setting's rows measured (``methods``: name -> the ``EvalModel.subject`` listed beside it)."""
    key = {"checkpoint": str(Path(checkpoint).resolve()),
           "checkpoint_rgbd": str(Path(checkpoint_rgbd).resolve()) if checkpoint_rgbd else None,
           "shards": str(Path(shards).resolve()), "views_per_scene": views_per_scene,
           "setting": dataclasses.asdict(setting), "methods": dict(sorted(methods.items()))}
    return json.loads(json.dumps(key))  # as it reads back (tuples as lists)


def _path(store: Path, key: dict[str, Any]) -> Path:
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    return Path(store) / f"{key['setting']['name'].replace(' ', '_').replace('/', '_')}-{digest}.json"


def stored_rows(store: Path, key: dict[str, Any]) -> list[dict[str, Any]] | None:
    """The rows stored under ``key`` in folder ``store`` (None when that measurement is not stored)."""
    path = _path(store, key)
    if not path.exists():
        return None
    saved = json.loads(path.read_text())
    return saved["rows"] if saved["key"] == key else None


def store_rows(store: Path, key: dict[str, Any], rows: list[dict[str, Any]]) -> Path:
    """Write one setting's ``rows`` under ``key`` with the machine that measured them; returns the file."""
    path = _path(store, key)
    atomic_write_json(path, {"key": key, "rows": rows, "machine": describe_machine()})
    return path
