"""The shard loader of one training rank, from the job's config (data section, augmentation, n_source, run seed)."""

from __future__ import annotations

from pathlib import Path

from sray.data_tools.loader.shard_loader import EpochLoader, make_train_loader
from sray.platform.config.train_config import TrainConfig


def job_loader(cfg: TrainConfig, rank: int, world_size: int, batches_per_epoch: int) -> EpochLoader:
    """``rank``'s loader of ``cfg``: ``batches_per_epoch`` samples an epoch, ``data.aug``, source labels if used."""
    data = cfg.data
    return make_train_loader(
        Path(data.shards), n_source=cfg.model.n_source, top_k=data.top_k, rays_per_batch=data.rays_per_batch,
        batches_per_epoch=batches_per_epoch, rank=rank, world_size=world_size, num_workers=data.loader_workers,
        seed=cfg.run.seed, augment=data.aug, source_labels=cfg.model.lambda_src_sem > 0,
        visit_samples=data.visit_samples, cache_scenes=data.cache_scenes)
