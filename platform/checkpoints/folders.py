"""Full-state training checkpoints: atomic, ``torch.load(weights_only=True)``-safe, latest + best. A checkpoint is a
folder ``step_<step:09d>/`` holding ``state.pt`` (tensors, dicts, lists, tuples, strings, numbers, bools, None only)
and ``meta.json``, assembled under a hidden name and renamed into place (a crash leaves the previous ones whole)."""

from __future__ import annotations

import json
import logging
import math
import os
import re
import shutil
import time
import uuid
from collections import OrderedDict
from pathlib import Path
from typing import Any

import torch

from sray.data_tools.atomic import replace_dir
from sray.platform.config.stored_format import outdated

log = logging.getLogger(__name__)

FORMAT = "sray-checkpoint"
VERSION = 2  # checkpoint format version; ``sray migrate`` converts older ones
STATE_FILE = "state.pt"
META_FILE = "meta.json"
_STEP_DIR = re.compile(r"^step_(\d{9,})$")
_EXACT_LEAVES = (str, int, float, bool, type(None))
"""Plain scalar types (exact: a NumPy float64 is a float subclass that weights_only refuses)."""
_TORCH_LEAVES = (torch.Tensor, torch.device, torch.dtype)


def check_weights_only_safe(obj: Any, where: str = "state") -> None:
    """TypeError naming the first entry ``torch.load(weights_only=True)`` would refuse."""
    if type(obj) in (dict, OrderedDict):
        for key, value in obj.items():
            if type(key) not in (str, int):
                raise TypeError(f"{where}: key {key!r} is a {type(key).__name__}; use str or int keys")
            check_weights_only_safe(value, f"{where}[{key!r}]")
    elif type(obj) in (list, tuple, torch.Size):
        for i, value in enumerate(obj):
            check_weights_only_safe(value, f"{where}[{i}]")
    elif not (type(obj) in _EXACT_LEAVES or isinstance(obj, _TORCH_LEAVES)):
        raise TypeError(f"{where} is a {type(obj).__module__}.{type(obj).__name__}, which "
                        "torch.load(weights_only=True) refuses; convert it (str for paths, lists or tensors "
                        "for arrays, dataclasses.asdict for configs)")


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_checkpoint(state: dict[str, Any], directory: Path, step: int, metric: float | None = None) -> Path:
    """Write ``state`` as checkpoint folder ``directory`` atomically (replacing one already there)."""
    check_weights_only_safe(state)
    directory = Path(directory)
    directory.parent.mkdir(parents=True, exist_ok=True)
    tag = f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tmp = directory.with_name(f".tmp-{directory.name}-{tag}")
    tmp.mkdir()
    try:
        with open(tmp / STATE_FILE, "wb") as f:
            torch.save(state, f)
            f.flush()
            os.fsync(f.fileno())
        meta = {"format": FORMAT, "version": VERSION, "step": int(step),
                "metric": None if metric is None or not math.isfinite(metric) else float(metric),
                "saved_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        (tmp / META_FILE).write_text(json.dumps(meta, indent=1) + "\n")
        _fsync_dir(tmp)
        # the same step may be saved again (a restarted job repeats steps): swap the folders
        replace_dir(tmp, directory, directory.with_name(f".old-{directory.name}-{tag}"))
        _fsync_dir(directory.parent)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return directory


def read_meta(directory: Path) -> dict[str, Any]:
    """The ``meta.json`` of a checkpoint folder; errors name the file and the fix."""
    path = Path(directory) / META_FILE
    try:
        meta = json.loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing; {directory} is not a complete sray checkpoint") from None
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path}: field 'format' is {meta.get('format')!r}, expected {FORMAT!r}")
    if meta.get("version") != VERSION:
        raise outdated(f"{path}: this checkpoint", meta.get("version"), VERSION)
    return meta


def load_checkpoint(path: Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Load a checkpoint folder (or its ``state.pt``) with ``torch.load(weights_only=True)``."""
    path = Path(path)
    file = path / STATE_FILE if path.is_dir() else path
    if not file.exists():
        raise FileNotFoundError(f"{file}: missing; expected a checkpoint folder holding {STATE_FILE}")
    return torch.load(file, map_location=map_location, weights_only=True)


class CheckpointManager:
    """Checkpoints under ``root``, known from their whole folders alone: save, ``latest``, ``best``, prune to last k."""

    def __init__(self, root: Path, keep_last: int = 3) -> None:
        """``keep_last``: newest checkpoints kept besides the best."""
        if keep_last < 1:
            raise ValueError(f"keep_last must be >= 1, got {keep_last}")
        self.root = Path(root)
        self.keep_last = keep_last
        self.root.mkdir(parents=True, exist_ok=True)
        self._recover()

    def _recover(self) -> None:
        """Undo an interrupted same-step replacement; remove leftovers of interrupted saves."""
        for old in self.root.glob(".old-step_*"):
            name = old.name[len(".old-"):].rsplit("-", 2)[0]
            if not (self.root / name).exists():
                os.rename(old, self.root / name)
                log.warning("restored checkpoint %s left aside by an interrupted save", self.root / name)
            else:
                shutil.rmtree(old, ignore_errors=True)
        for tmp in self.root.glob(".tmp-step_*"):
            shutil.rmtree(tmp, ignore_errors=True)

    def entries(self) -> list[tuple[int, float | None, Path]]:
        """(step, metric, folder) of every complete checkpoint, by step."""
        out = []
        for child in self.root.iterdir():
            match = _STEP_DIR.match(child.name)
            if match and (child / META_FILE).exists() and (child / STATE_FILE).exists():
                out.append((int(match.group(1)), read_meta(child)["metric"], child))
        return sorted(out, key=lambda e: e[0])

    def save(self, state: dict[str, Any], step: int, metric: float | None = None) -> Path:
        """Write the checkpoint of ``step`` (with its validation metric, if any) and prune; its folder."""
        path = write_checkpoint(state, self.root / f"step_{int(step):09d}", step, metric)
        self._prune()
        return path

    def latest(self) -> Path | None:
        """Folder of the highest-step complete checkpoint, or None."""
        entries = self.entries()
        return entries[-1][2] if entries else None

    def best(self) -> Path | None:
        """Folder of the checkpoint with the highest metric (earliest on ties), or None if none has one."""
        scored = [(-m, s, p) for s, m, p in self.entries() if m is not None]
        return min(scored)[2] if scored else None

    def _prune(self) -> None:
        entries = self.entries()
        keep = {p for _, _, p in entries[-self.keep_last:]} | {self.best()}
        for _, _, path in entries:
            if path not in keep:
                shutil.rmtree(path, ignore_errors=True)


def resolve_checkpoint(path: Path) -> Path:
    """The checkpoint folder of itself, a job's ``checkpoints/`` or a job (best, else latest); FileNotFoundError."""
    path = Path(path).resolve()
    for root in (path, path / "checkpoints"):
        if (root / STATE_FILE).is_file():
            return root
        if root.is_dir() and any(root.glob("step_*")):
            manager = CheckpointManager(root)
            if found := manager.best() or manager.latest():
                return found
    raise FileNotFoundError(f"{path}: no sray checkpoint here; pass a step_XXXXXXXXX folder (holding state.pt), "
                            "a job's checkpoints/ folder or the job folder")
