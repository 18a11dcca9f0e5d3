"""Atomic file writes, importable from every part of sray: a temporary sibling ``.<name>.tmp<pid>`` (same file
system), fsync, then one rename, so a reader sees the old file or the whole new one, never a partial file."""

from __future__ import annotations

import io
import json
import os
import re
import shutil
from pathlib import Path
from typing import Any

TEMP_NAME = re.compile(r"^\..+\.tmp\d+$")
"""Names of this module's temporary files (left behind only by a killed process)."""


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (parent folders are created); no temporary file survives an error."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: Path, obj: object) -> None:
    """Write ``obj`` as indented JSON (one space, trailing newline) to ``path`` atomically."""
    atomic_write_text(path, json.dumps(obj, indent=1) + "\n")


def save_png(fig: Any, path: Path, dpi: int) -> Path:
    """Render the matplotlib figure ``fig`` to PNG in memory and write it to ``path`` atomically; returns ``path``."""
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    atomic_write_bytes(path, buf.getvalue())
    return Path(path)


def replace_dir(ready: Path, target: Path, aside: Path) -> None:
    """Rename the complete folder ``ready`` to ``target``; an existing ``target`` is first renamed to
    ``aside`` and deleted only once the new one is in place (a crash leaves one whole folder there)."""
    if target.exists():
        os.replace(target, aside)
        os.replace(ready, target)
        shutil.rmtree(aside)
    else:
        os.replace(ready, target)
