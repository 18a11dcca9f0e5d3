"""The model, data and budget settings one variant of ``sray lab accuracy`` changes (the variants themselves are
:mod:`sray.lab.accuracy.plan`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Variant:
    """The model settings a row of the benchmark changes."""

    attention: str = "full"
    """``model.attention``."""
    weight_map: str = "radial"
    """``model.weight_map``."""
    weight_inputs: str = "view"
    """``model.weight_inputs`` (``cross-view``: the weight net also reads each view's distance from the valid
    views' mean feature and their variance)."""
    tau: float | None = None
    """``model.tau`` (None: the recipe's): the bound of the semantic-aware weights, tau/m < w_i < 1/(tau m)."""
    inputs: str = "rgb"
    """``model.inputs`` (``rgbd``: the source views' depth guides the samples)."""
    fine_samples: str = "union"
    """``model.fine_samples`` (``new``: the fine pass evaluates only the resampled depths, as the official
    code; half the training step on a CPU, docs/performance.md). ``union`` for every variant but
    ``full-new``, as when their cells were trained, although the model default is ``new`` since the
    ``full``/``full-new`` comparison."""
    n_heads: int | None = None
    """``model.n_heads`` (None: the recipe's): fewer, wider heads do less softmax work per token."""
    lambda_src_sem: float = 0.0
    """``model.lambda_src_sem``: weight of the source views' per-pixel semantic loss on the encoder (0 = off)."""
    lambda_depth: float = 0.0
    """``model.lambda_depth``: weight of the training-time depth loss against the query's depth (0 = off; the test
    protocol stays RGB, the descriptor says training read depth)."""
    warmup_2d_steps: int = 0
    """``optim.warmup_2d_steps``: first steps trained on the source views' labels alone (0 = none)."""
    visit_samples: int = 16
    """``data.visit_samples``: consecutive samples drawn from one scene before the loader picks the next
    (1 = scenes interleaved step by step)."""
    cache_scenes: int = 2
    """``data.cache_scenes``: decoded scenes the loader keeps."""
    train_scenes: int | None = None
    """Training rooms of the cell's world (None: the preset world's). The world keeps the preset's seed, views,
    image size and test scenes: the generator cycles its 5 room types over the train scenes first, so a count
    that differs from the preset's by a multiple of 5 (48 -> 198, 498) leaves every test scene unchanged, which
    the cell checks before it trains."""
    step_cap: int | None = None
    """``optim.steps`` of a CPU-budgeted cell (None: the recipe's cap). A budget, not a model or data setting: cells
    that differ only here form one arm of the accuracy-against-CPU-time chart."""
    cpu_seconds: float | None = None
    """``optim.cpu_seconds`` of a CPU-budgeted cell (None: the recipe's budget). A budget too, like ``step_cap``."""
    overrides: tuple[str, ...] = ()
    """``section.field=value`` assignments applied after every other setting: the step-cost levers, in the form
    ``sray lab recipe-step --lever`` measures them, and settings no other field names (the lr decay's start)."""
