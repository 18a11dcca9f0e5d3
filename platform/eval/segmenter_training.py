"""Train the plain 2D segmenter (:mod:`sray.platform.eval.segmenter`) for a budget of CPU seconds.

Data: the training loader (``make_train_loader(..., source_labels=True)``) over the train scenes, with the
recipe's augmentation; each step fits the m source images of one sample to their labels. Those sources
come from each train scene's source pool (its ``train`` split minus its held-out ``test`` views), so no
test-scene view and no held-out view is read; the class weights are counted over the same pool.

Budget: ``time.process_time()`` of this process (every thread of it) from the first sample to the last
step, data loading included (the loader runs in-process, no workers); the class-weight count before it is
not part of the budget. The loop stops at the first step that ends past the budget (at least one step).
Adam at a constant learning rate.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from sray.data_tools.loader.class_stats import balanced_weights, count_pixels
from sray.data_tools.loader.augment import Augmentation
from sray.data_tools.loader.shard_loader import make_train_loader
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import Manifest, read_manifest
from sray.platform.eval.segmenter import Segmenter, SegmenterConfig, SegmenterRecord, save_segmenter

POOL_RULE = "each train scene's source pool: its train split minus its held-out test views"
"""The views the segmenter (and the probe) may read, as recorded with them."""


def train_scene_names(manifest: Manifest, where: Path) -> tuple[list[str], list[str]]:
    """(train scene names, their shared class names); ValueError naming the manifest when there is no train
    scene or their label spaces differ."""
    names = sorted(s for s, e in manifest.scenes.items() if e.meta.get("role", "train") == "train")
    if not names:
        raise ValueError(f"{where}: no scene has role 'train'; the segmenter trains on train scenes only")
    classes = {tuple(manifest.scenes[s].meta["class_names"]) for s in names}
    if len(classes) != 1:
        raise ValueError(f"{where}: the train scenes use {len(classes)} label spaces; train on one label space")
    return names, list(classes.pop())


def pool_class_weights(shards: Path, manifest: Manifest, scenes: list[str], n_classes: int, mode: str) -> list[float]:
    """Class weights (``balanced_weights`` of ``mode``) from the labelled pixels of the scenes' source pools
    only; [] for ``none``."""
    if mode == "none":
        return []
    counts = np.zeros(n_classes + 1, np.int64)
    for scene in scenes:
        views = read_scene_views(shards, manifest.scenes[scene])
        pool = source_pool(SceneMeta.from_json(manifest.scenes[scene].meta))
        counts += count_pixels((views[v].label() for v in pool), n_classes)
    return balanced_weights(counts[:n_classes], mode)


def train_segmenter(shards: Path, cpu_seconds: float, out: Path, seed: int = 0, *,
                    augment: Augmentation | None = None, class_balance: str = "inverse-sqrt", n_source: int = 8,
                    top_k: int = 12, lr: float = 1e-3, feat_dim: int = 32, visit_samples: int = 1,
                    cache_scenes: int = 4, progress: bool = True) -> SegmenterRecord:
    """Train a segmenter on the train scenes of ``shards`` for ``cpu_seconds`` (see the module doc), save it in
    folder ``out`` and return its record. ``augment``: the training loader's augmentation (None = none);
    ``class_balance``: ``none``, ``inverse-sqrt`` or ``inverse``; ``n_source`` images per step drawn from
    ``top_k`` ranked neighbours (the augmentation may draw fewer); ``visit_samples``: consecutive steps on one
    scene before the loader picks the next (1 = scenes interleaved step by step: at an equal CPU budget its
    labels carried into unseen rooms score higher than with 16 consecutive samples per scene, docs/benchmarks.md
    "Ceilings"),
    ``cache_scenes`` decoded scenes kept."""
    if cpu_seconds <= 0:
        raise ValueError(f"cpu_seconds is {cpu_seconds}; give the segmenter a positive CPU budget")
    shards = Path(shards)
    manifest = read_manifest(shards)
    scenes, class_names = train_scene_names(manifest, shards / "manifest.json")
    weights = pool_class_weights(shards, manifest, scenes, len(class_names), class_balance)
    torch.manual_seed(seed)
    model = Segmenter(SegmenterConfig(n_classes=len(class_names), feat_dim=feat_dim, class_weights=tuple(weights)))
    model.train()
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    loader = make_train_loader(shards, n_source=n_source, top_k=top_k, rays_per_batch=1, batches_per_epoch=1000,
                               rank=0, world_size=1, num_workers=0, seed=seed, scenes=scenes, augment=augment,
                               source_labels=True, visit_samples=visit_samples, cache_scenes=cache_scenes)
    steps = images = 0
    losses: list[float] = []
    start = time.process_time()
    bar = tqdm(total=round(cpu_seconds), desc="segmenter", unit="CPU s", disable=not progress)
    while steps == 0 or time.process_time() - start < cpu_seconds:
        for sample in loader:
            loss = model.loss(sample.sources.rgb, sample.sources.label)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            steps, images = steps + 1, images + sample.sources.rgb.shape[0]
            losses.append(float(loss.detach()))
            bar.update(min(round(time.process_time() - start), round(cpu_seconds)) - bar.n)
            if time.process_time() - start >= cpu_seconds:
                break
    bar.close()
    spent = time.process_time() - start
    training = {"cpu_seconds_budget": cpu_seconds, "cpu_seconds": spent, "steps": steps, "images": images,
                "clock": "time.process_time of the training loop, data loading included (no loader workers)",
                "seed": seed, "shards": str(shards), "scenes": scenes, "views": POOL_RULE,
                "augmentation": dataclasses.asdict(augment or Augmentation()), "class_balance": class_balance,
                "class_names": class_names, "optimizer": f"Adam, constant lr {lr}", "n_source": n_source,
                "top_k": top_k, "visit_samples": visit_samples, "cache_scenes": cache_scenes,
                "final_loss": float(np.mean(losses[-20:]))}
    save_segmenter(model.eval(), training, out)
    return SegmenterRecord(model.cfg, training)
