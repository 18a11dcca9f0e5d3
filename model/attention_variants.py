"""The table of Cross-Reprojection Attention variants: each is the sequence of attention stages it runs.

A stage is one pre-norm attention block over one grouping of the contextual space M (R, m, N, C):

* ``intra``: over the N samples of each (ray, view) — intra-view radial attention (appendix L1-L4);
* ``cross``: over the m views of each (ray, sample) — cross-view sparse attention (L5-L6);
* ``dense``: over all m · N tokens of a ray — the paper's costly baseline.

``full`` (the paper's CRA) runs ``intra`` then ``cross``; ``none`` runs no attention. A variant whose
stages attend along the ray (``intra`` or ``dense``) also adds the embedding of each sample's
normalised depth first (:data:`POSITION_STAGES`). Adding a variant is one entry here; a new way of
grouping tokens is one function in ``cra.py``'s stage table as well.
"""

from __future__ import annotations

ATTENTION_VARIANTS: dict[str, tuple[str, ...]] = {
    "full": ("intra", "cross"),
    "intra": ("intra",),
    "cross": ("cross",),
    "none": (),
    "dense": ("dense",),
}
"""Variant name (``SRayConfig.attention``) -> its stages, in the order they run."""

POSITION_STAGES = frozenset({"intra", "dense"})
"""Stages that attend along the ray, so need each sample's position (its normalised depth)."""
