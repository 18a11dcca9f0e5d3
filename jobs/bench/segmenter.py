"""``sray bench segmenter``: train the 2D segmenter (encoder + linear head) that ``2d-transfer`` and the ceilings'
rows read, for a CPU-second budget, with a recipe's images and augmentation."""

from __future__ import annotations

from pathlib import Path

from sray.platform.config.recipes import get_recipe
from sray.platform.config.train_config import apply_override
from sray.platform.eval.segmenter import SegmenterRecord
from sray.platform.eval.segmenter_training import train_segmenter


def run_segmenter(shards: Path, cpu_seconds: float, out: Path, recipe: str = "synth-cpu-hour",
                  seed: int = 0, max_steps: int | None = None, encoder_width: int | None = None,
                  overrides: tuple[str, ...] = ()) -> SegmenterRecord:
    """Train the 2D segmenter with ``recipe``'s augmentation, class balance, source counts and encoder for
    ``cpu_seconds`` (or ``max_steps``, when sooner), resuming an interrupted training left in ``out``; saved in
    ``out``. ``encoder_width``: the encoder's first-layer width instead of the recipe's ``model.encoder_width``.
    ``overrides``: ``section.field=value``
    assignments applied to the recipe first (``data.aug.colour_ev=0``: the same training without exposure jitter);
    ValueError names a field that does not exist."""
    cfg = get_recipe(recipe)
    for assignment in overrides:
        apply_override(cfg, assignment)
    result = train_segmenter(shards, cpu_seconds, out, seed, augment=cfg.data.aug,
                             class_balance=cfg.data.class_balance, n_source=cfg.model.n_source,
                             top_k=cfg.data.top_k, feat_dim=cfg.model.feat_dim, max_steps=max_steps,
                             encoder_width=cfg.model.encoder_width if encoder_width is None else encoder_width)
    print(f"segmenter saved in {out}: {result.budget()}, final loss {result.training['final_loss']:.3f}")
    return result
