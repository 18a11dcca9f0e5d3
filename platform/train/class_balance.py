"""The class-frequency-aware semantic loss: weights from the training scenes' pixel frequencies."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from sray.data_tools.loader.class_stats import BALANCE_MODES, balanced_weights, shard_pixel_counts
from sray.platform.config.train_config import TrainConfig


def set_class_weights(cfg: TrainConfig) -> None:
    """Fill ``cfg.model.class_weights`` from the train scenes of ``cfg.data.shards`` as
    ``cfg.data.class_balance`` asks (nothing for ``none`` or when weights are set already).

    The counts are over every view of every train scene in the shards (labelled pixels only); the
    weights follow :func:`sray.data_tools.loader.class_stats.balanced_weights` and are recorded in the
    job's config, so a resumed job and its checkpoints keep them.
    """
    if cfg.data.class_balance not in BALANCE_MODES:
        raise ValueError(f"data.class_balance is {cfg.data.class_balance!r}; use one of {BALANCE_MODES}")
    if cfg.data.class_balance == "none" or cfg.model.class_weights:
        return
    names, per_scene = shard_pixel_counts(Path(cfg.data.shards), roles=("train",))
    if len(names) != cfg.model.n_classes:
        raise ValueError(f"{cfg.data.shards}/manifest.json: {len(names)} classes, model.n_classes is "
                         f"{cfg.model.n_classes}; train on data of the model's label space")
    counts = sum(per_scene.values())[:-1]  # (n_classes,): the ignore id's pixels are left out
    weights = tuple(balanced_weights(counts, cfg.data.class_balance))
    cfg.model = dataclasses.replace(cfg.model, class_weights=weights)
