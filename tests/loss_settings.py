"""Stand-alone loss settings for ``render_loss`` tests (a ``losses.LossSettings`` without a model config)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class LossConfig:
    """The fields ``render_loss`` reads, with the paper's defaults."""

    lambda_sem: float = 1.0
    lambda_rgb: float = 1.0
    ignore_id: int = 255
    class_weights: tuple[float, ...] = ()
