"""Saving matplotlib figures as PNG files atomically (the whole file or the old one, never a partial one)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_bytes


def save_png(fig: Any, path: Path, dpi: int) -> Path:
    """Render ``fig`` to PNG in memory and write it to ``path`` through one atomic rename; returns ``path``."""
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)
