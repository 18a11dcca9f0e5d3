"""``sray bench segmenter``'s training: the 2D segmenter of ``2d-transfer`` for a CPU-second budget."""

from __future__ import annotations

from pathlib import Path

from sray.platform.config.recipes import get_recipe
from sray.platform.config.train_config import apply_override
from sray.platform.eval.segmenter import SegmenterRecord
from sray.platform.eval.segmenter_training import train_segmenter


def run_segmenter(shards: Path, cpu_seconds: float, out: Path, recipe: str = "synth-cpu-hour",
                  seed: int = 0, max_steps: int | None = None, encoder_width: int | None = None,
                  overrides: tuple[str, ...] = ()) -> SegmenterRecord:
    """Train the 2D segmenter into ``out`` (resuming one left there) with ``recipe``'s augmentation, class balance,
    source counts and encoder (``encoder_width`` overrides its first-layer width) for ``cpu_seconds`` or ``max_steps``,
    whichever ends first. ``overrides``: ``section.field=value`` applied to the recipe first (ValueError: no field)."""
    cfg = get_recipe(recipe)
    for assignment in overrides:
        apply_override(cfg, assignment)
    result = train_segmenter(shards, cpu_seconds, out, seed, augment=cfg.data.aug,
                             class_balance=cfg.data.class_balance, n_source=cfg.model.n_source,
                             top_k=cfg.data.top_k, feat_dim=cfg.model.feat_dim, max_steps=max_steps,
                             encoder_width=cfg.model.encoder_width if encoder_width is None else encoder_width)
    print(f"segmenter saved in {out}: {result.budget()}, final loss {result.training['final_loss']:.3f}")
    return result
