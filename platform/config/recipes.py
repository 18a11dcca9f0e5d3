"""Training recipes: functions returning a ``TrainConfig`` for ``sray train --recipe NAME``; ``--set`` overrides."""

from __future__ import annotations

from collections.abc import Callable

from sray.data_tools.loader.augment import Augmentation
from sray.model.config import SRayConfig
from sray.platform.config.held_out_render import HeldOutRender
from sray.platform.config.train_config import DataSettings, OptimSettings, RunSettings, TrainConfig


def synth_small() -> TrainConfig:
    """Minutes on two CPU workers: small images, few rays and samples (CI, the stability suite, sweeps)."""
    return TrainConfig(recipe="synth-small", model=SRayConfig(n_source=4, n_coarse=24, n_fine=24),
                       data=DataSettings(shards="outputs/demo/shards", top_k=6, rays_per_batch=256),
                       optim=OptimSettings(steps=300, lr=1e-3, lr_final=2e-4),
                       run=RunSettings(experiment="sray-synth-small", workers=2, val_every=100, ckpt_every=100))


DEMO_STEPS = 600
"""``optim.steps`` of ``synth-demo``: a few minutes of wall time on a 2-core machine, about half of the demo."""


def synth_demo() -> TrainConfig:
    """``synth-cpu-hour`` scaled to minutes on ``sray demo``'s world (19 training rooms, 160x120): ``synth-small``'s
    model, rays, sources; no view augmentation (unmeasured here), full CRA (intra-only scored lower): study
    ``demo-recipe`` (docs/benchmarks.md)."""
    cfg = synth_small()
    cfg.recipe = "synth-demo"
    cfg.model.lambda_src_sem = 1.0
    cfg.data.visit_samples, cfg.data.cache_scenes, cfg.data.class_balance = 1, 4, "inverse-sqrt"
    cfg.optim.steps, cfg.optim.warmup_2d_steps = DEMO_STEPS, DEMO_STEPS // 3
    cfg.run.experiment = "sray-synth-demo"
    cfg.run.val_every = cfg.run.ckpt_every = DEMO_STEPS // 2
    return cfg


CPU_HOUR_SHARDS = "outputs/studies/worlds/train498-test4-v40-120x160-s0/shards"
"""``synth-cpu-hour``'s shards: the 498-room world of ``sray lab study --worlds jobs/studies/hour-recipe.yaml``."""


def synth_cpu_hour() -> TrainConfig:
    """One hour of pretraining on 2 CPU cores, built to generalize (each choice won its arm in
    docs/studies/hour-recipe.md): 7,200 CPU seconds end the job; the 20,000-step cap only bounds the learning-rate
    schedule on a faster machine. Figures: the README's recipe card (``python -m sray.lab.publish``)."""
    return TrainConfig(
        recipe="synth-cpu-hour",
        model=SRayConfig(n_source=8, n_coarse=24, n_fine=24, attention="intra", lambda_src_sem=1.0),
        data=DataSettings(shards=CPU_HOUR_SHARDS, top_k=12, rays_per_batch=256, visit_samples=1, cache_scenes=4,
                          val_views_per_scene=1, val_scenes=4, class_balance="inverse-sqrt",
                          held_out=HeldOutRender(n_source=0, stride=4, fast_stride=1),
                          aug=Augmentation(colour_ev=0.3, channel_ev=0.1, noise_sigma=3.0, min_source=2,
                                           source_scale=0.25)),
        optim=OptimSettings(steps=20_000, cpu_seconds=7200.0, lr=1e-3, lr_final=1e-4, warmup_steps=100,
                            warmup_2d_steps=1500),
        run=RunSettings(experiment="sray-synth-cpu-hour", workers=2, log_every=20, val_every=700, ckpt_every=200),
    )


def synth_gpu_minutes() -> TrainConfig:
    """Minutes of pretraining on one GPU: ``synth-cpu-hour`` for 3,600 steps (about six minutes on an H200,
    docs/gpu.md) instead of a CPU budget; ``sray gpu-check``'s ``minutes`` stage trains it and records the mIoU."""
    cfg = synth_cpu_hour()
    cfg.recipe = "synth-gpu-minutes"
    cfg.data.rays_per_batch, cfg.data.loader_workers = 4096, 6
    cfg.optim.steps, cfg.optim.cpu_seconds, cfg.optim.warmup_2d_steps = 3600, 0.0, 400
    cfg.run = RunSettings(experiment="sray-synth-gpu-minutes", workers=1, cpus_per_worker=8.0, gpus_per_worker=1.0,
                          precision="bf16", log_every=100, val_every=3600, ckpt_every=600)
    return cfg


def paper(name: str, shards: str, steps: int) -> TrainConfig:
    """The paper's settings (a GPU job) under recipe name ``name``, on ``shards``, for ``steps`` steps."""
    return TrainConfig(
        recipe=name,
        data=DataSettings(shards=shards, top_k=12, rays_per_batch=1024, loader_workers=4),
        optim=OptimSettings(steps=steps),
        run=RunSettings(experiment=f"sray-{name}", workers=1, gpus_per_worker=1.0, precision="bf16", val_every=2000,
                        ckpt_every=2000),
    )


RECIPES: dict[str, Callable[[], TrainConfig]] = {
    "synth-small": synth_small,
    "synth-demo": synth_demo,
    "synth-cpu-hour": synth_cpu_hour,
    "synth-gpu-minutes": synth_gpu_minutes,
    "synth-paper": lambda: paper("synth-paper", "outputs/synth/shards", 100_000),  # procedural scenes
    "scannet-paper": lambda: paper("scannet-paper", "data/scannet/shards", 260_000),  # 60 scenes, 320x240 (appendix)
    "replica-paper": lambda: paper("replica-paper", "data/replica/shards", 100_000),  # 12 train scenes (appendix)
}
"""Recipe name -> function returning a fresh config."""


def get_recipe(name: str) -> TrainConfig:
    """A fresh config of the named recipe; ValueError lists the known names."""
    try:
        return RECIPES[name]()
    except KeyError:
        raise ValueError(f"unknown recipe {name!r}; known: {', '.join(RECIPES)}") from None
