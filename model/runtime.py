"""``Runtime``: how an ``SRayModel`` is run (code path, rays per pass), apart from what it is (``SRayConfig``): speed
and memory, never a parameter; outputs only within float32 rounding. Every rendering call takes one."""

from __future__ import annotations

from dataclasses import dataclass

IMPLS = ("fast", "reference")
"""Implementations of the per-sample computation: ``fast`` gathers source features with an ``embedding_bag``
(``grid_sample``'s bilinear weights, a much cheaper backward) and builds per-view tensors in (R, N, m) order;
``reference`` is the unoptimised path that benchmarks and equivalence tests compare against."""


@dataclass(frozen=True)
class Runtime:
    """Implementation and rays per pass of the S-Ray network's calls; validated on creation."""

    impl: str = "fast"
    """Implementation of the per-sample computation, one of ``IMPLS``."""
    chunk: int = 0
    """Rays per forward pass of ``render_image`` and the evaluations (bounds memory); 0: by device (``ray_chunks``)."""
    train_piece: int = 0
    """Rays per piece of a training step's loss (``piecewise_loss``: same loss and gradients, one piece's tensors alive
    at a time); 0: by device (``ray_chunks``). Gradients inside a smaller piece are not loss-scaled: use 0 with fp16."""

    def __post_init__(self) -> None:
        """Reject settings no call can run with, naming the field and the fix."""
        if self.impl not in IMPLS:
            raise ValueError(f"sray.model.runtime.Runtime: field `impl` is {self.impl!r}; use one of {IMPLS}.")
        for name in ("chunk", "train_piece"):
            if int(getattr(self, name)) < 0:
                raise ValueError(f"sray.model.runtime.Runtime: field `{name}` is {getattr(self, name)}; use a "
                                 "positive count of rays, or 0 (by device).")
