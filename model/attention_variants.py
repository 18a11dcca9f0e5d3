"""The Cross-Reprojection Attention variants as sequences of stages over M (R, m, N, C) (``cra.STAGES``): ``intra``
over each (ray, view)'s N samples (appendix L1-L4), ``cross`` over each (ray, sample)'s m views (L5-L6), ``dense``
over all m * N tokens of a ray (the paper's costly baseline)."""

from __future__ import annotations

ATTENTION_VARIANTS: dict[str, tuple[str, ...]] = {
    "full": ("intra", "cross"), "intra": ("intra",), "cross": ("cross",), "none": (), "dense": ("dense",)}
"""Variant name (``SRayConfig.attention``) -> its stages, in the order they run."""

POSITION_STAGES = frozenset({"intra", "dense"})
"""Stages that attend along the ray, so need each sample's position (its normalised depth)."""
