"""``Runtime``: how an ``SRayModel`` is run, apart from what it is.

``SRayConfig`` is the network and its loss, what a checkpoint stores. The settings here choose the code path
of the per-sample networks and how many rays one pass handles: they change speed and memory, never a
parameter, and the outputs only within float32 rounding. A caller passes them to every ``SRayModel`` call that
renders (``render_rays``, ``ray_renderer``, ``render_image``, ``training_loss``), so one loaded model runs
either way without being changed; a training job holds them in its config's ``runtime`` section.
"""

from __future__ import annotations

from dataclasses import dataclass

IMPLS = ("fast", "reference")
"""Implementations of the per-sample computation (``Runtime.impl``): ``fast`` (default) gathers the source
features with an ``embedding_bag`` (the same bilinear weights as ``grid_sample``, a much cheaper backward) and
builds every per-view tensor directly in (R, N, m) order; ``reference`` is the first, unoptimised path, kept so
that benchmarks and equivalence tests compare against it."""


@dataclass(frozen=True)
class Runtime:
    """Implementation and rays per pass of the S-Ray network's calls; validated on creation."""

    impl: str = "fast"
    """Implementation of the per-sample computation, one of ``IMPLS`` (same parameters, same outputs within
    float32 rounding; ``reference`` is the unoptimised path)."""
    chunk: int = 0
    """Rays rendered per forward pass by ``render_image`` and the evaluations (bounds their memory); 0 (default)
    leaves it to the device: 256 on a CPU, 4096 on a GPU (``ray_chunks``)."""
    train_piece: int = 0
    """Rays per piece of a training step's loss (``piecewise_loss``: same loss and gradients, one piece's tensors
    alive at a time); 0 (default) leaves it to the device: 256 on a CPU, the whole batch on a GPU
    (``ray_chunks``). Inside a piece of fewer rays than the batch, gradients are not loss-scaled, so use 0 with
    fp16."""

    def __post_init__(self) -> None:
        """Reject settings no call can run with, naming the field and the fix."""
        if self.impl not in IMPLS:
            raise ValueError(f"sray.model.runtime.Runtime: field `impl` is {self.impl!r}; use one of {IMPLS}.")
        for name in ("chunk", "train_piece"):
            if int(getattr(self, name)) < 0:
                raise ValueError(f"sray.model.runtime.Runtime: field `{name}` is {getattr(self, name)}; use a "
                                 "positive count of rays, or 0 (by device).")
