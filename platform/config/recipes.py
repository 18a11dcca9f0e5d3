"""Training recipes: named functions that return a complete ``TrainConfig``.

``sray train --recipe NAME`` starts from one of these; ``--set section.field=value`` and the
common flags override fields. Paper settings (implementation details and appendix): 1024 rays,
8 source views, Adam with lr 1e-3 decaying to 5e-5, coarse (64) + fine (64) samples, 250k steps.
"""

from __future__ import annotations

from collections.abc import Callable

from sray.data_tools.loader.augment import Augmentation
from sray.model.config import SRayConfig
from sray.platform.config.held_out_render import HeldOutRender
from sray.platform.config.optim_settings import OptimSettings
from sray.platform.config.train_config import DataSettings, RunSettings, TrainConfig


def synth_small() -> TrainConfig:
    """Minutes on two CPU workers: small images, few rays and samples (CI, the stability suite, sweeps)."""
    return TrainConfig(
        recipe="synth-small",
        model=SRayConfig(n_source=4, n_coarse=24, n_fine=24),
        data=DataSettings(shards="outputs/demo/shards", top_k=6, rays_per_batch=256,
                          loader_workers=1, val_views_per_scene=2),
        optim=OptimSettings(steps=300, lr=1e-3, lr_final=2e-4, grad_clip=1.0),
        run=RunSettings(experiment="sray-synth-small", workers=2, cpus_per_worker=1.0, log_every=10,
                        val_every=100, ckpt_every=100),
    )


DEMO_STEPS = 600
"""``optim.steps`` of ``synth-demo``: a few minutes of wall time on a 2-core machine, about half of the demo."""

DEMO_WARMUP_2D = 200
"""``optim.warmup_2d_steps`` of ``synth-demo``: its first third trains the encoder on the source views' labels alone."""


def synth_demo() -> TrainConfig:
    """The demo's recipe: ``synth-cpu-hour`` scaled down to minutes on ``sray demo``'s world (19 training rooms,
    160x120).

    ``synth-small``'s model, rays and sources, trained the hour recipe's way: class-balanced semantic loss, scenes
    interleaved step by step, the encoder also learning from its source views' labels, and a 2D-only warm-up of
    ``DEMO_WARMUP_2D`` of its ``DEMO_STEPS`` steps; no view augmentation (not measured at this length). Its data
    order is the loader's default (``data.epoch_steps`` 0: one loader epoch per checkpoint interval), chosen without
    scoring orders on any room: the demo's unseen rooms report its zero-shot score and choose nothing. The demo's
    larger world is what lets these losses and the warm-up lift zero-shot accuracy above ``synth-small``'s: on the
    earlier 4-room world they gained nothing. Its attention stays full CRA, unlike the hour recipe's intra-only stage:
    at this scale the cross-view stage costs little next to the encoder, and intra-only scored lower on both seeds
    tried and saved no training CPU (study ``demo-recipe``, listed in docs/benchmarks.md).
    """
    cfg = synth_small()
    cfg.recipe = "synth-demo"
    cfg.model.lambda_src_sem = 1.0
    cfg.data.visit_samples, cfg.data.cache_scenes, cfg.data.class_balance = 1, 4, "inverse-sqrt"
    cfg.optim.steps, cfg.optim.warmup_2d_steps = DEMO_STEPS, DEMO_WARMUP_2D
    cfg.run.experiment = "sray-synth-demo"
    cfg.run.val_every = cfg.run.ckpt_every = DEMO_STEPS // 2
    return cfg


CPU_HOUR_SECONDS = 7200.0
"""CPU budget of ``synth-cpu-hour``: one hour of both cores of a 2-core machine, counted over the training ranks and
their loader processes (``optim.cpu_seconds``), so the job ends after about an hour of wall time on such a machine
and after the same CPU time wherever it runs; the steps that buys depend on the machine (``CPU_HOUR_STEP_CAP``)."""

CPU_HOUR_STEP_CAP = 20_000
"""Step cap of ``synth-cpu-hour``: beyond what its CPU budget reaches on a 2-core machine, so the budget ends the
job; the steps it stops after depend on what a CPU second buys on the host (each stored trial records its ray steps
and its machine). The cap only bounds the learning-rate schedule on a much faster machine (``budget_lr_factor``
follows the larger of the step and CPU-budget fractions). The recipe is trained until its budget is spent because
the steps the budget buys beyond a lower cap raised held-out accuracy on every paired seed (docs/studies/hour-recipe.md:
``hour-intra-uncapped`` against the capped ``hour-intra``; docs/studies/hour-budget.md for twice the budget)."""

CPU_HOUR_WARMUP_2D = 1500
"""``optim.warmup_2d_steps`` of ``synth-cpu-hour``: its first steps train the encoder and its source-view head on
the source views' labels alone, before any ray is rendered (a small share of its budget: a 2D step renders
nothing)."""


CPU_HOUR_SHARDS = "outputs/studies/worlds/train498-test4-v40-120x160-s0/shards"
"""Default shards of ``synth-cpu-hour``: the 498-room world of its study (jobs/studies/hour-recipe.yaml), which
``sray lab study --worlds jobs/studies/hour-recipe.yaml`` generates in the studies' default work folder."""


def synth_cpu_hour() -> TrainConfig:
    """One hour of pretraining on 2 CPU cores (a budget of CPU seconds, not steps), built to generalize rather
    than to memorize its rooms.

    498 procedural rooms at 160x120, 40 views each, at ``CPU_HOUR_SHARDS`` (``sray lab study --worlds
    jobs/studies/hour-recipe.yaml`` generates them there; ``--set data.shards=DIR`` trains on any other world): at the
    same CPU budget, more rooms transferred better to unseen rooms at every room count tried, and the model stopped
    memorizing its training rooms (docs/studies/hour-recipe.md); generating them is not counted in the budget.
    Each sample has 2-8 source views drawn from its 12 top-ranked neighbours and rendered at a random share of their
    resolution, with per-view exposure, white-balance and sensor-noise jitter; the semantic loss is weighted by
    inverse-square-root class frequency so small classes count. Scenes are interleaved step by step (one sample
    per scene visit) and the encoder also learns from its source views' labels: together they let the model label
    objects, where either alone gained nothing measurable (trials ``source-loss-600``). Its first ``CPU_HOUR_WARMUP_2D``
    steps train the encoder and that head on the source labels alone, before any ray is rendered: the encoder then
    carries the category information the ray loss alone was too sparse to teach it, and nearly every class rose over
    three seeds (docs/studies/hour-recipe.md: ``hour-warm2d`` against ``hour-498``). Its cross-reprojection attention
    keeps only the intra-view stage (``model.attention=intra``): level with the full block over three paired seeds
    for less training CPU, and above no attention (docs/studies/hour-recipe.md: ``hour-intra``, ``hour-warm2d``,
    ``hour-none``). It trains until its CPU budget is spent (``CPU_HOUR_STEP_CAP`` lies beyond it): the steps the
    cheaper attention saves are trained, not left unspent. Evaluation uses 8 sources. Its published figures are the
    README's recipe card and headline, generated from the stored trials by ``python -m sray.lab.publish``.
    """
    return TrainConfig(
        recipe="synth-cpu-hour",
        model=SRayConfig(n_source=8, n_coarse=24, n_fine=24, attention="intra", lambda_src_sem=1.0),
        data=DataSettings(shards=CPU_HOUR_SHARDS, top_k=12, rays_per_batch=256,
                          loader_workers=1, visit_samples=1, cache_scenes=4,
                          val_views_per_scene=1, val_scenes=4,
                          held_out=HeldOutRender(n_source=0, stride=4, fast_stride=1),
                          class_balance="inverse-sqrt",
                          aug=Augmentation(colour_ev=0.3, channel_ev=0.1, noise_sigma=3.0, min_source=2,
                                           source_scale=0.25)),
        optim=OptimSettings(steps=CPU_HOUR_STEP_CAP, cpu_seconds=CPU_HOUR_SECONDS, lr=1e-3, lr_final=1e-4,
                            warmup_steps=100, grad_clip=1.0, warmup_2d_steps=CPU_HOUR_WARMUP_2D),
        run=RunSettings(experiment="sray-synth-cpu-hour", workers=2, cpus_per_worker=1.0, log_every=20,
                        val_every=700, ckpt_every=200),
    )


GPU_MINUTES_STEPS = 3600
"""``optim.steps`` of ``synth-gpu-minutes``: about six minutes at the bf16 training rate at 4,096 rays that
``sray gpu-check``'s ``recipe`` stage measured for this model family on an H200 at 64+64 samples (its GPU check,
docs/gpu.md); the recipe's 24+24 samples cost less per ray, so six minutes is the upper end until the ``minutes``
stage records its own."""

GPU_MINUTES_WARMUP_2D = 400
"""``optim.warmup_2d_steps`` of ``synth-gpu-minutes``: the hour recipe's 2D-only warm-up, scaled with its step count
(1,500 of about 6,500 steps there)."""


def synth_gpu_minutes() -> TrainConfig:
    """Minutes of pretraining on one GPU: ``synth-cpu-hour``'s model, losses, augmentation and world (the 498
    rooms at ``CPU_HOUR_SHARDS``), scored with its protocol (8 fixed sources, whole images, fast render s1 c0.9,
    the same unseen and held-out rooms), at 4,096 rays per step in bf16 on one GPU worker, for a step count
    (``GPU_MINUTES_STEPS``) instead of a CPU budget. ``sray gpu-check``'s ``minutes`` stage generates the world,
    trains it and records its training minutes and its zero-shot and held-out mIoU (docs/gpu.md)."""
    cfg = synth_cpu_hour()
    cfg.recipe = "synth-gpu-minutes"
    cfg.data.rays_per_batch, cfg.data.loader_workers = 4096, 6
    cfg.optim.steps, cfg.optim.cpu_seconds, cfg.optim.warmup_2d_steps = GPU_MINUTES_STEPS, 0.0, GPU_MINUTES_WARMUP_2D
    cfg.run = RunSettings(experiment="sray-synth-gpu-minutes", workers=1, cpus_per_worker=8.0, gpus_per_worker=1.0,
                          precision="bf16", log_every=100, val_every=GPU_MINUTES_STEPS, ckpt_every=600)
    return cfg


def synth_paper() -> TrainConfig:
    """The paper's settings on procedural scenes (a GPU job)."""
    return TrainConfig(
        recipe="synth-paper",
        model=SRayConfig(),
        data=DataSettings(shards="outputs/synth/shards", top_k=12, rays_per_batch=1024,
                          loader_workers=4),
        optim=OptimSettings(steps=100_000),
        run=RunSettings(experiment="sray-synth-paper", workers=1, gpus_per_worker=1.0,
                        precision="bf16", val_every=2000, ckpt_every=2000),
    )


def scannet_paper() -> TrainConfig:
    """The paper's ScanNet setting: 60 train scenes at 320x240, 260k steps (appendix)."""
    cfg = synth_paper()
    cfg.recipe = "scannet-paper"
    cfg.data.shards = "data/scannet/shards"
    cfg.optim.steps = 260_000
    cfg.run.experiment = "sray-scannet-paper"
    return cfg


def replica_paper() -> TrainConfig:
    """The paper's Replica setting: 12 train scenes, 100k steps (appendix)."""
    cfg = synth_paper()
    cfg.recipe = "replica-paper"
    cfg.data.shards = "data/replica/shards"
    cfg.optim.steps = 100_000
    cfg.run.experiment = "sray-replica-paper"
    return cfg


RECIPES: dict[str, Callable[[], TrainConfig]] = {
    "synth-small": synth_small,
    "synth-demo": synth_demo,
    "synth-cpu-hour": synth_cpu_hour,
    "synth-gpu-minutes": synth_gpu_minutes,
    "synth-paper": synth_paper,
    "scannet-paper": scannet_paper,
    "replica-paper": replica_paper,
}
"""Recipe name -> function returning a fresh config."""


def get_recipe(name: str) -> TrainConfig:
    """A fresh config of the named recipe; ValueError lists the known names."""
    try:
        return RECIPES[name]()
    except KeyError:
        raise ValueError(f"unknown recipe {name!r}; known: {', '.join(RECIPES)}") from None
