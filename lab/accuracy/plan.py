"""The plan of ``sray lab accuracy``: its variants, cells, worlds and presets (data only; the run is
:mod:`sray.lab.accuracy.run`, a cell :mod:`sray.lab.accuracy.cells`, the tables
:mod:`sray.lab.accuracy.tables`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

from sray.data_tools.synth.world import World
from sray.lab.accuracy.levers import (HOUR_INVERSE, HOUR_LR_RAYS, HOUR_SAMPLES_16, HOUR_TWICE, ROOMS_998,
                                              NARROW_12_WARMUP_2D, SCREEN_DEPTH, SCREEN_GROUP_NORM, SCREEN_LR_RAYS,
                                              SCREEN_NARROW_12, SCREEN_OCCL, SCREEN_OCCL_T5, SCREEN_RAYS_128,
                                              SCREEN_LR_2X, SCREEN_RAY_BALANCE, SCREEN_RAYS_512, SCREEN_ROOMS_998,
                                              SCREEN_SAMPLES_16, SCREEN_SRC_3, SCREEN_VIEWS_8, SCREEN_WARM_750,
                                              SCREEN_WEIGHT_AVERAGE, SCREEN_WEIGHT_DECAY, SCREEN_WIDE_24,
                                              WIDE_24_WARMUP_2D)
from sray.lab.accuracy.variant import Variant
from sray.model.fast_render import FastRender
from sray.platform.config.recipes import CPU_HOUR_SECONDS, CPU_HOUR_WARMUP_2D

LONG = "long"
"""Variant name of the cell that pretrains for the preset's ``long_steps`` with the first hour recipe's
settings (full CRA, union fine pass, 16 samples per scene visit, no source-view loss, no CPU budget)."""

HOUR = "hour"
"""Variant name of the cell that pretrains with the preset recipe's settings but its 2D warm-up and its attention
(full CRA here), at its own budget (``synth-cpu-hour``: CPU seconds), on the preset's world (48 rooms for
``cpu-small``, the recipe's first world)."""

ROOMS_198, ROOMS_498 = "hour-198", "hour-498"
"""Variant names of ``hour`` trained on 198 and 498 procedural rooms instead of the preset world's; ``hour-498`` is
``hour-warm2d`` without its 2D warm-up (``synth-cpu-hour``'s settings, budget and world otherwise, with full CRA)."""

RECIPE_ROOMS = 498
"""Training rooms of ``synth-cpu-hour``'s world (the preset world's other sizes and its test scenes)."""

HOUR_NONE = "hour-none"
"""Variant name of the hour recipe (498 rooms, 2D warm-up) without cross-reprojection attention (the attention
question at the hour budget, and the no-CRA model of the stability suite)."""

HOUR_CROSS, HOUR_INTRA = "hour-cross", "hour-intra"
"""Variant names of ``hour-warm2d`` with only the cross-view or only the intra-view attention stage of CRA (the
paper's Table 4 ablation, asked on the model that labels objects); ``hour-intra`` is ``synth-cpu-hour`` capped at
``CAPPED_STEPS`` like every other CPU-budgeted cell but the recipe's own."""
HOUR_WARM = "hour-warm2d"
"""Variant name of ``hour-498`` whose first 1,500 steps train the encoder on the source views' labels alone
(``optim.warmup_2d_steps``), within the same CPU budget, with full CRA: ``synth-cpu-hour`` but for its attention;
measured because at equal CPU a plain 2D segmenter's encoder carried 13 points more category information than
``hour-498``'s (docs/benchmarks.md, "On the 498-room recipe model")."""

HOUR_INTRA_UNCAPPED = "hour-intra-uncapped"
"""Variant name of ``synth-cpu-hour`` exactly as it is (its settings, attention, budget and world:
``RECIPE_VARIANT``): ``hour-intra`` with the recipe's own step cap, which lies beyond its CPU budget, so the budget
stops it."""

SCREEN, SCREEN_WARM = "screen", "screen-warm3k"
"""Variant names of the screening pair, at ``SCREEN_SECONDS`` of CPU: ``synth-cpu-hour`` exactly as it is but for
its budget, and the same with its 2D warm-up doubled to 3,000 steps (``optim.warmup_2d_steps``). Measured because
on the recipe's models a linear probe still reads 6.7 points less from S-Ray's encoder than from a 2D segmenter's
trained for the same CPU, while the field read at the true surface scores no better than the render (the ceilings
of docs/benchmarks.md): recognition, not geometry, is where zero-shot accuracy is lost, and a 2D step costs under half
a ray step."""

SCREEN_SECONDS = CPU_HOUR_SECONDS / 2
"""CPU budget of the screening cells: half the recipe's, so a paired arm and its baseline fit one session of the
2-core machine."""

CAPPED_STEPS = 5000
"""``optim.steps`` of every CPU-budgeted cell but the recipe's: the step cap the recipe had when they were trained,
so their stored cells stay valid; on the 2-core machines it stops ``hour-intra`` after 4,400-4,700 of its 7,200 CPU s
and the full-CRA cells after 5,200-5,500."""

RECIPE_VARIANT = HOUR_INTRA_UNCAPPED
"""The variant that is ``synth-cpu-hour`` exactly as it is: the ``cpu-small`` preset's headline (a test keeps them
equal); its three paired seeds against ``hour-intra`` are in docs/benchmarks.md, "The hour recipe at its CPU
budget"."""

WARM_2D_STEPS = CPU_HOUR_WARMUP_2D
"""``optim.warmup_2d_steps`` of ``hour-warm2d`` and the recipe."""

CPU_BUDGETED = (HOUR, ROOMS_198, ROOMS_498, HOUR_NONE, HOUR_CROSS, HOUR_INTRA, HOUR_WARM, HOUR_INTRA_UNCAPPED,
                SCREEN, SCREEN_WARM, SCREEN_DEPTH, SCREEN_OCCL, SCREEN_OCCL_T5, SCREEN_RAYS_128, SCREEN_RAYS_512,
                SCREEN_SAMPLES_16, SCREEN_ROOMS_998, SCREEN_LR_RAYS, HOUR_LR_RAYS, HOUR_SAMPLES_16, HOUR_INVERSE,
                SCREEN_WIDE_24, SCREEN_NARROW_12, SCREEN_SRC_3, SCREEN_RAY_BALANCE, SCREEN_LR_2X,
                SCREEN_WARM_750, SCREEN_GROUP_NORM, SCREEN_WEIGHT_DECAY, SCREEN_WEIGHT_AVERAGE, SCREEN_VIEWS_8,
                HOUR_TWICE)
"""Variants whose cells train for a CPU budget (the preset recipe's own, or ``Variant.cpu_seconds``) instead of a
step budget."""

_HOUR_SETTINGS = Variant(fine_samples="new", lambda_src_sem=1.0, visit_samples=1, cache_scenes=4, step_cap=CAPPED_STEPS)
_UNWARMED_RECIPE = replace(_HOUR_SETTINGS, train_scenes=RECIPE_ROOMS)
_WARM_SETTINGS = replace(_UNWARMED_RECIPE, warmup_2d_steps=WARM_2D_STEPS)
_RECIPE = replace(_WARM_SETTINGS, attention="intra", step_cap=None)
_SCREEN = replace(_RECIPE, cpu_seconds=SCREEN_SECONDS)
_SAMPLES_16 = ("model.n_coarse=16", "model.n_fine=16")
_LR_RAYS = ("optim.lr_decay_start=rays",)

VARIANT_SETTINGS = {"full": Variant(), "cross": Variant("cross"), "intra": Variant("intra"), "none": Variant("none"),
                    "full-affine": Variant(weight_map="affine"), "full-rgbd": Variant(inputs="rgbd"),
                    "full-new": Variant(fine_samples="new"), "full-new-h2": Variant(fine_samples="new", n_heads=2),
                    "full-new-src": Variant(fine_samples="new", lambda_src_sem=1.0),
                    "full-new-src-w": Variant(fine_samples="new", lambda_src_sem=1.0, warmup_2d_steps=100),
                    "full-new-mix": Variant(fine_samples="new", visit_samples=1, cache_scenes=4),
                    "full-new-src-mix": Variant(fine_samples="new", lambda_src_sem=1.0, visit_samples=1,
                                                cache_scenes=4),
                    LONG: Variant(),
                    HOUR: _HOUR_SETTINGS,
                    ROOMS_198: replace(_HOUR_SETTINGS, train_scenes=198),
                    ROOMS_498: _UNWARMED_RECIPE,
                    HOUR_NONE: replace(_WARM_SETTINGS, attention="none"),
                    HOUR_CROSS: replace(_WARM_SETTINGS, attention="cross"),
                    HOUR_INTRA: replace(_WARM_SETTINGS, attention="intra"),
                    HOUR_WARM: _WARM_SETTINGS,
                    HOUR_INTRA_UNCAPPED: _RECIPE,
                    SCREEN: _SCREEN,
                    SCREEN_WARM: replace(_SCREEN, warmup_2d_steps=2 * WARM_2D_STEPS),
                    SCREEN_DEPTH: replace(_SCREEN, lambda_depth=0.1),
                    SCREEN_OCCL: replace(_SCREEN, weight_inputs="cross-view"),
                    SCREEN_OCCL_T5: replace(_SCREEN, weight_inputs="cross-view", tau=0.5),
                    SCREEN_RAYS_128: replace(_SCREEN, overrides=("data.rays_per_batch=128",)),
                    SCREEN_RAYS_512: replace(_SCREEN, overrides=("data.rays_per_batch=512",)),
                    SCREEN_SAMPLES_16: replace(_SCREEN, overrides=_SAMPLES_16),
                    SCREEN_ROOMS_998: replace(_SCREEN, train_scenes=ROOMS_998),
                    SCREEN_LR_RAYS: replace(_SCREEN, overrides=_LR_RAYS),
                    HOUR_LR_RAYS: replace(_RECIPE, overrides=_LR_RAYS),
                    HOUR_SAMPLES_16: replace(_RECIPE, overrides=_SAMPLES_16),
                    HOUR_INVERSE: replace(_RECIPE, overrides=("data.class_balance=inverse",)),
                    SCREEN_WIDE_24: replace(_SCREEN, warmup_2d_steps=WIDE_24_WARMUP_2D,
                                            overrides=("model.encoder_width=24",)),
                    SCREEN_NARROW_12: replace(_SCREEN, warmup_2d_steps=NARROW_12_WARMUP_2D,
                                              overrides=("model.encoder_width=12",)),
                    SCREEN_SRC_3: replace(_SCREEN, lambda_src_sem=3.0),
                    SCREEN_RAY_BALANCE: replace(_SCREEN, overrides=("data.ray_balance=0.5",)),
                    SCREEN_LR_2X: replace(_SCREEN, overrides=("optim.lr=2e-3", "optim.lr_final=2e-4")),
                    SCREEN_WARM_750: replace(_SCREEN, warmup_2d_steps=WARM_2D_STEPS // 2),
                    SCREEN_GROUP_NORM: replace(_SCREEN, overrides=("model.encoder_norm=group",)),
                    SCREEN_WEIGHT_DECAY: replace(_SCREEN, overrides=("optim.weight_decay=0.3",)),
                    SCREEN_WEIGHT_AVERAGE: replace(_SCREEN, overrides=("optim.ema_decay=0.998",)),
                    SCREEN_VIEWS_8: replace(_SCREEN, overrides=("data.aug.min_source=0",)),
                    HOUR_TWICE: replace(_RECIPE, cpu_seconds=2 * CPU_HOUR_SECONDS)}
"""Variant name -> its settings; ``full-affine`` is full CRA with the first (affine) semantic-aware weight map instead
of the default radial one, ``full-rgbd`` full CRA given the source views' depth, ``full-new`` full CRA whose fine
pass evaluates the resampled depths only, ``full-new-h2`` the same with 2 heads of 16 channels instead of 4 of 8;
``full-new-src`` full-new with the source views' per-pixel semantic loss on the encoder (weight 1),
``full-new-src-w`` the same after a 100-step 2D-only warm-up within the budget; ``full-new-mix`` and
``full-new-src-mix`` are full-new and full-new-src with scenes interleaved step by step (one sample per scene visit,
4 scenes cached) instead of 16 consecutive samples per scene; ``hour`` holds ``synth-cpu-hour``'s settings without
its 2D warm-up, with full CRA, on the preset's 48 rooms; ``hour-198`` and ``hour-498`` are ``hour`` on 198 and 498
training rooms (the same test rooms; generating them is not counted in the CPU budget); ``hour-warm2d`` is
``hour-498`` whose first 1,500 steps are the 2D-only warm-up (full CRA); ``hour-none`` is ``hour-warm2d`` without
cross-reprojection attention, ``hour-cross`` and ``hour-intra`` with only its cross-view or only its intra-view stage
(``hour-intra-uncapped``: the recipe exactly, stopped by its CPU budget; every other CPU-budgeted cell also stops at
``CAPPED_STEPS``); ``screen`` and ``screen-warm3k`` are the recipe and the recipe with a 3,000-step warm-up, both at
the screening budget ``SCREEN_SECONDS``; ``screen-depth`` is ``screen`` with the training-time depth loss (weight
0.1), ``screen-occl`` with the weight net also reading the cross-view statistics, ``screen-occl-t5`` the same at tau
0.5 (the two occlusion levers, docs/model.md); ``screen-rays128`` and ``screen-rays512`` are ``screen`` with 128
and 512 query rays per rank-step, ``screen-samples16`` with 16+16 samples per ray (step-cost levers); ``screen-998``
is ``screen`` on 998 training rooms, ``screen-lr-rays`` with the lr decay started at the first ray step, and
``hour-lr-rays`` the recipe with that decay, at the recipe's budget; ``hour-samples16`` is the recipe with 16+16
samples per ray, ``hour-inverse`` the recipe with inverse-frequency class weights; ``screen-w24`` is ``screen`` with
a 24-channel encoder and its 2D warm-up cut to the same CPU, ``screen-w12`` with a 12-channel encoder and its 2D
warm-up lengthened to the same CPU, ``screen-src3`` with the source views' semantic loss weighted 3,
``screen-raybal`` with query pixels drawn favouring each image's small classes (``data.ray_balance=0.5``),
``screen-lr2x`` with its whole learning-rate schedule doubled (``optim.lr=2e-3``, ``optim.lr_final=2e-4``),
``screen-warm750`` with its 2D warm-up halved to 750 steps, ``screen-gn`` with group norm in every encoder layer
instead of instance norm (``model.encoder_norm=group``), ``screen-wd`` with AdamW's decoupled weight decay 0.3
(``optim.weight_decay=0.3``), ``screen-ema`` scored on an exponential moving average of its weights
(``optim.ema_decay=0.998``), ``screen-views8`` with 8 source views in every training sample
(``data.aug.min_source=0``) instead of 2 to 8."""


EXPERIMENT = "sray-bench-accuracy"
"""Tracking experiment of every pretraining, evaluation and finetune of the benchmark."""


@dataclass(frozen=True)
class Cell:
    """One pretraining + zero-shot evaluation: a variant (``VARIANT_SETTINGS``) and a training seed."""

    variant: str
    seed: int

    @property
    def key(self) -> str:
        """File and job name part: ``full-s0``."""
        return f"{self.variant}-s{self.seed}"

    @classmethod
    def parse(cls, text: str) -> Cell:
        """``full:0`` or ``full-s0`` -> Cell; ValueError names the accepted forms and variants."""
        variant, sep, seed = text.rpartition(":") if ":" in text else text.rpartition("-s")
        if not sep or variant not in VARIANT_SETTINGS or not seed.isdigit():
            raise ValueError(f"cell {text!r}: write VARIANT:SEED (e.g. full:0) with VARIANT one of "
                             f"{', '.join(VARIANT_SETTINGS)}")
        return cls(variant, int(seed))


def seeds(variant: str, n: int) -> tuple[Cell, ...]:
    """Cells of ``variant`` with training seeds 0..n-1."""
    return tuple(Cell(variant, s) for s in range(n))


@dataclass(frozen=True)
class Preset:
    """Sizes and plan of one benchmark preset."""

    world: World
    recipe: str
    """Pretraining recipe every cell starts from (``platform/config/recipes.py``)."""
    overrides: tuple[str, ...]
    """``section.field=value`` assignments applied to the recipe in every cell (sizes of small presets)."""
    long_steps: int | None
    """Steps of the ``long`` cell (None = the recipe's own step cap)."""
    ablation_steps: int
    """Steps of every other cell (the shorter ablation budget)."""
    validations: int
    """Held-out validations logged during each pretraining (the cell evaluates its last checkpoint)."""
    ckpt_every: int
    """Checkpoint interval of each pretraining: the most an interrupted cell repeats."""
    plan: tuple[Cell, ...]
    """Cells in the order they run (the long model first: its number is the headline)."""
    eval_sources: int
    """Source views per query in the zero-shot evaluation."""
    eval_fast: FastRender | None
    """Render mode of the zero-shot evaluation (None = the full hierarchical renderer)."""
    budget_s: float
    """Wall-clock budget of each finetune (both methods)."""
    budgets: tuple[float, ...]
    """Equal-budget read-off points (seconds)."""
    fleet_eval_stride: int
    """Finetune curves score every n-th pixel in each direction of the held-out views."""
    fleet_gpus_per_task: float
    """GPUs each finetune task takes (0 on a CPU machine)."""
    headline: str = LONG
    """Variant of the headline model: the preset's recipe exactly as it is (settings, budget and world), the model
    its targets are read on and its fleet finetunes from."""


PRESETS = {
    "cpu-small": Preset(
        world=World(train_scenes=48, test_scenes=4, views=40, height=120, width=160),
        recipe="synth-cpu-hour", overrides=(), long_steps=2500, ablation_steps=600, validations=2, ckpt_every=200,
        plan=(Cell(LONG, 0), *seeds("full", 1), *seeds("none", 1), Cell("full", 1), Cell("none", 1),
              Cell("full", 2), Cell("none", 2), Cell("cross", 0), Cell("intra", 0), Cell("full-rgbd", 0),
              *seeds("full-new", 3), *seeds("full-new-h2", 3), *seeds("full-new-src", 3), Cell("full-new-src-w", 0),
              *seeds("full-new-src-mix", 3), *seeds("full-new-mix", 3), Cell(HOUR, 0), Cell(ROOMS_198, 0),
              *seeds(ROOMS_498, 3), *seeds(HOUR_WARM, 3), *seeds(HOUR_NONE, 3), Cell(HOUR_CROSS, 0),
              *seeds(HOUR_INTRA, 3), *seeds(HOUR_INTRA_UNCAPPED, 3), Cell(SCREEN, 0), Cell(SCREEN_WARM, 0),
              Cell(SCREEN_DEPTH, 0), Cell(SCREEN_OCCL, 0), Cell(SCREEN_OCCL_T5, 0), Cell(SCREEN, 1),
              Cell(SCREEN_OCCL, 1), Cell(SCREEN, 2), Cell(SCREEN_OCCL, 2), *seeds(SCREEN_RAYS_128, 3), Cell(HOUR, 1),
              Cell(HOUR, 2), Cell(ROOMS_198, 1), Cell(ROOMS_198, 2), *seeds(SCREEN_SAMPLES_16, 3),
              *seeds(SCREEN_ROOMS_998, 3), *seeds(SCREEN_LR_RAYS, 3), Cell(HOUR_LR_RAYS, 0),
              Cell(HOUR_SAMPLES_16, 0), Cell(SCREEN_RAYS_512, 2),
              Cell(HOUR_INVERSE, 0), Cell(SCREEN_WIDE_24, 2), Cell(SCREEN_NARROW_12, 2),
              Cell(SCREEN_NARROW_12, 0), Cell(SCREEN_SRC_3, 2), Cell(SCREEN_SRC_3, 0),
              Cell(SCREEN_RAY_BALANCE, 0), Cell(SCREEN_LR_2X, 0), Cell(SCREEN_WARM_750, 0),
              Cell(SCREEN_GROUP_NORM, 0), *seeds(SCREEN_WEIGHT_DECAY, 3), *seeds(SCREEN_WEIGHT_AVERAGE, 3),
              *seeds(SCREEN_VIEWS_8, 3), *seeds(HOUR_TWICE, 3)),
        eval_sources=8, eval_fast=FastRender(pixel_stride=1, confidence=0.9),
        budget_s=120.0, budgets=(30.0, 60.0, 120.0), fleet_eval_stride=4,
        fleet_gpus_per_task=0.0, headline=RECIPE_VARIANT),
    "gpu": Preset(
        world=World(train_scenes=96, test_scenes=8, views=100, height=240, width=320),
        recipe="synth-paper", overrides=("data.aug.min_source=2", "data.class_balance=inverse-sqrt",
                                         "data.aug.colour_ev=0.3", "data.aug.channel_ev=0.1",
                                         "data.aug.noise_sigma=3.0"),
        long_steps=20_000, ablation_steps=5_000, validations=4, ckpt_every=1_000,
        plan=(*seeds(LONG, 3), *seeds("full", 3), *seeds("none", 3), Cell("cross", 0), Cell("intra", 0),
              Cell("full-affine", 0), Cell("full-rgbd", 0), Cell("full-new", 0)),
        eval_sources=8, eval_fast=None, budget_s=600.0, budgets=(60.0, 120.0, 300.0, 600.0), fleet_eval_stride=2,
        fleet_gpus_per_task=0.5),
}
"""Benchmark presets: ``cpu-small`` fits this 2-core machine over a few runs of about an hour;
``gpu`` is the paper-size run for a GPU machine."""


def headline_variant(p: Preset) -> str:
    """The variant of ``p``'s headline model, the one its targets are read on and its fleet finetunes from: the
    recipe as it is (``Preset.headline``: ``hour-intra-uncapped`` for ``cpu-small``) when the plan holds it; else
    the recipe's first form at its step budget (``long``)."""
    return p.headline if any(c.variant == p.headline for c in p.plan) else LONG
