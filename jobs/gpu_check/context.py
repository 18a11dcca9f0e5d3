"""What every ``sray gpu-check`` stage receives: the device, the sizes (real or dry run) and the folders."""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path

import torch

from .report import StageResult

INSTALLED_AT = Path(__file__).resolve().parents[2]
"""The folder holding the installed ``sray.jobs``: the checkout's root under an editable install (or the folders
linked onto the path), ``site-packages/sray`` under a wheel."""
FULL_STACK = ("ray", "mlflow", "webdataset")
"""What the stages that run sray's commands need beyond torch (the GPU image may lack them)."""


class NotACheckout(RuntimeError):
    """``sray gpu-check`` from an installation without the checkout's ``tests/`` and ``docs/`` beside it."""


def checkout_root() -> Path:
    """The checkout sray is installed from (its ``tests/`` feed the tests stage, ``docs/`` the reports), whatever the
    working directory; :class:`NotACheckout` under a wheel install."""
    missing = [f"{name}/" for name in ("tests", "docs") if not (INSTALLED_AT / name).is_dir()]
    if missing:
        raise NotACheckout(f"sray is installed at {INSTALLED_AT}, which has no {' or '.join(missing)}: run it from a "
                           "git checkout of sray installed with pip install -e . (or with its folders on the path, "
                           "docs/gpu.md)")
    return INSTALLED_AT


@dataclass(frozen=True)
class CheckContext:
    """The run's settings, shared by all stages; a dry run has toy sizes on the CPU (the suite runs it)."""

    device: torch.device
    dry_run: bool
    out: Path
    """Work folder: the report, scratch data and logs."""
    repo: Path
    """Checkout root."""

    @property
    def image_hw(self) -> tuple[int, int]:
        """Image size of the model checks: 240 x 320 on a GPU."""
        return (32, 40) if self.dry_run else (240, 320)

    @property
    def samples(self) -> tuple[int, int]:
        """(coarse, fine) samples per ray: the paper's 64 + 64 on a GPU."""
        return (4, 4) if self.dry_run else (64, 64)

    @property
    def views(self) -> int:
        """Source views: the paper's 8 on a GPU."""
        return 2 if self.dry_run else 8

    @property
    def rays(self) -> int:
        """Rays per training step: the paper's 1024 on a GPU."""
        return 32 if self.dry_run else 1024

    def low_precisions(self) -> list[str]:
        """The autocast precisions to compare with fp32 here: bf16 and fp16 on CUDA, bf16 on the CPU."""
        return ["bf16", "fp16"] if self.device.type == "cuda" else ["bf16"]


def has_module(name: str) -> bool:
    """Whether ``name`` can be imported here."""
    return importlib.util.find_spec(name) is not None


def skipped_without(needs: tuple[str, ...], stage: str) -> StageResult | None:
    """A skipped result naming the packages of ``needs`` not installed here (None when all are)."""
    missing = [m for m in needs if not has_module(m)]
    return StageResult("skipped", f"{', '.join(missing)} not installed here: {stage}") if missing else None
