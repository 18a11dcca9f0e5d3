"""sray: generalizable semantic radiance fields (S-Ray). The Python API is :func:`load`::

    import sray
    model = sray.load("outputs/jobs/<job>/checkpoints")          # a trained checkpoint
    labels = model.label(images, poses, intrinsics)               # uint8 (N,H,W,3), (N,4,4) OpenCV c2w, (3,3) K

The folders setup.py maps to ``sray.<folder>`` sit inside this package in a wheel and beside it in a checkout,
whose root is then added to the search path (docs/architecture.md). ``load`` is imported on first use (PEP 562),
so ``import sray.data_tools...`` stays free of torch."""

from __future__ import annotations

from pathlib import Path
from typing import Any

_HERE = Path(__file__).resolve().parent
if not (_HERE / "model").is_dir():  # editable install / source checkout: the folders are siblings of sray/
    __path__.append(str(_HERE.parent))  # type: ignore[name-defined]  # noqa: F821  (a package's __path__)

__all__ = ["load"]


def __getattr__(name: str) -> Any:
    """``sray.load`` (:func:`sray.platform.label.labeller.load`), imported when first asked for."""
    if name == "load":
        from sray.platform.label.labeller import load

        return load
    raise AttributeError(f"module 'sray' has no attribute {name!r}")
