"""Which render a held-out evaluation inside a job uses: validation (``data.val_render``) and the finetune
fleet's held-out scores (``finetune.eval_render``).

Both already score a strided pixel grid of their own (``data.val_downscale``, ``finetune.eval_stride``),
so their fast mode renders exactly those pixels (pixel stride 1, nothing upsampled) and saves only
where the model is sure: a ray whose coarse pass reaches ``confidence`` keeps its coarse result, the
others get a fine pass on the resampled depths (``sray.model.fast_render``). Its cost in mIoU is
measured, paired against the full render, by ``sray bench speed-accuracy`` (docs/benchmarks.md).
"""

from __future__ import annotations

from sray.model.fast_render import FastRender

HELD_OUT_RENDERS = ("fast", "full")
"""``fast``: the fast render mode on the evaluation's own pixels; ``full``: the whole coarse + fine render."""


def held_out_fast(render: str, confidence: float, field: str) -> FastRender | None:
    """The fast mode of a held-out evaluation (None for the full render); ValueError naming ``field``
    (the config field that holds ``render``) and the fix on a bad value."""
    if render not in HELD_OUT_RENDERS:
        raise ValueError(f"{field} is {render!r}; use one of {HELD_OUT_RENDERS} (fast: the fine pass only where "
                         "the coarse pass is unsure; full: the whole render)")
    if not 0.0 < confidence:
        raise ValueError(f"{field.replace('render', 'fast_confidence')} is {confidence}; it must be > 0 "
                         "(a value > 1 gives every ray a fine pass)")
    return FastRender(pixel_stride=1, confidence=confidence) if render == "fast" else None
