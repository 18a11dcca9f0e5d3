"""A new sweep as the command line (or a test) asks for it, before any check."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sray.platform.config.train_config import TrainConfig
from sray.platform.sweep.options import SweepOptions
from sray.platform.sweep.spec import Param


@dataclass
class SweepRequest:
    """A new sweep, as the command line (or a test) asks for it."""

    name: str
    """Unique name: the sweep's folder under ``out`` and its parent run's name."""
    out: Path
    """Folder holding sweeps."""
    base: TrainConfig
    """The config every trial starts from (a recipe with the fixed overrides)."""
    params: list[Param]
    """The swept fields."""
    options: SweepOptions
    """How the sweep runs."""
