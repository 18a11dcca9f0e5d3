"""How a held-out view is rendered and scored, for validation (``data.held_out``), the fleet (``finetune.held_out``),
``sray eval`` and ``sray render``; the fast render's mIoU cost: ``sray bench speed-accuracy`` (docs/benchmarks.md)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from sray.model.fast_render import FastRender

HELD_OUT_RENDERS = ("fast", "full")
"""``fast``: the fast render mode; ``full``: the whole coarse + fine render at every scored pixel."""


@dataclass
class HeldOutRender:
    """Sources, pixels and render of a held-out evaluation; checked by the config that holds it (:meth:`check`)."""

    n_source: int = 8
    """Fixed sources per held-out view, top-ranked by the shards (paper: 8); 0 = ``model.n_source`` (validation's)."""
    stride: int = 1
    """Every ``stride``-th pixel is scored, in each direction (1 = whole images, the only stride with SSIM)."""
    render: str = "fast"
    """One of ``HELD_OUT_RENDERS``: ``fast`` (``fast_stride`` and ``fast_confidence``) or ``full``."""
    fast_stride: int = 8
    """Fast render: rays every ``fast_stride``-th scored pixel, upsampled to the others (1 = every scored pixel)."""
    fast_confidence: float = 0.9
    """Fast render: a ray whose coarse softmax maximum reaches this skips the fine pass (> 1: no ray skips it)."""
    fast_temperature: float = 1.0
    """Fast render: temperature of that softmax (1 = uncalibrated; ``sray eval --calibrate`` fits it)."""

    def check(self, name: Callable[[str], str]) -> None:
        """ValueError naming the first bad setting as ``name(field)`` spells it (``--render``), and the fix."""
        if self.render not in HELD_OUT_RENDERS:
            raise ValueError(f"{name('render')} is {self.render!r}; use one of {HELD_OUT_RENDERS} (fast: the fine "
                             "pass only where the coarse pass is unsure; full: the whole render)")
        if not 0.0 < self.fast_confidence:
            raise ValueError(f"{name('fast_confidence')} is {self.fast_confidence}; it must be > 0 (a value > 1 "
                             "gives every ray a fine pass)")
        if not 0.0 < self.fast_temperature:
            raise ValueError(f"{name('fast_temperature')} is {self.fast_temperature}; it must be > 0 (1 = "
                             "uncalibrated)")
        for field in ("stride", "fast_stride"):
            if int(getattr(self, field)) < 1:
                raise ValueError(f"{name(field)} is {getattr(self, field)}; it must be a positive integer")
        if self.n_source < 0:
            raise ValueError(f"{name('n_source')} is {self.n_source}; give a number of source views, or 0 for the "
                             "model's own model.n_source")

    def fast(self) -> FastRender | None:
        """The fast render mode of these settings, None for the full render."""
        return (FastRender(self.fast_stride, self.fast_confidence, self.fast_temperature) if self.render == "fast"
                else None)

    def sources(self, model_sources: int) -> int:
        """Source views per held-out view: ``n_source``, or ``model_sources`` (the model's) when it is 0."""
        return self.n_source or model_sources
