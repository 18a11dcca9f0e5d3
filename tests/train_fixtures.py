"""Tiny procedural shards and a tiny training config for the training tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from sray.model.runtime import Runtime
from sray.platform.config.recipes import get_recipe
from sray.platform.config.train_config import TrainConfig


@pytest.fixture(scope="session")
def tiny_shards(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2 train scenes + 1 unseen test scene, 20 views of 32x40 each, sharded."""
    from sray.data_tools.shards.writer import write_shards
    from sray.data_tools.synth.dataset import generate_dataset

    root = tmp_path_factory.mktemp("tiny")
    generate_dataset(root / "scenes", n_train=2, n_test=1, n_views=20, height=32, width=40, seed=3, progress=False)
    write_shards(root / "scenes", root / "shards", neighbours=8)
    return root / "shards"


def tiny_config(shards: Path, out: Path, **run: object) -> TrainConfig:
    """A seconds-per-run config: 2 workers, 64 rays in pieces of 24 (DDP over the piecewise loss), 8+8 samples,
    checkpoints every 5 steps."""
    cfg = get_recipe("synth-small")
    cfg.model.n_source, cfg.model.n_coarse, cfg.model.n_fine = 3, 8, 8
    cfg.runtime = Runtime(chunk=1024, train_piece=24)
    cfg.data.shards, cfg.data.top_k, cfg.data.rays_per_batch = str(shards), 4, 64
    cfg.data.loader_workers, cfg.data.val_views_per_scene, cfg.data.held_out.stride = 0, 1, 2
    cfg.optim.steps, cfg.optim.lr, cfg.optim.lr_final = 20, 3e-3, 1e-3
    cfg.run.output_dir, cfg.run.tracking_uri = str(out / "jobs"), f"sqlite:///{out / 'mlflow.db'}"
    cfg.run.workers, cfg.run.log_every, cfg.run.val_every, cfg.run.ckpt_every = 2, 1, 10, 5
    cfg.run.max_failures, cfg.run.system_metrics_s = 1, 0.5
    for key, value in run.items():
        setattr(cfg.run, key, value)
    return cfg
