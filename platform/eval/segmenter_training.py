"""Train the plain 2D segmenter for a budget of CPU seconds (the loop's ``time.process_time``, loading included, over
resumed runs) on the train scenes' source pools only; each loader epoch writes ``STATE_FILE``, from which a resumed
run reaches an uninterrupted run's weights; the file goes once the segmenter is saved."""

from __future__ import annotations

import dataclasses
import io
import time
from typing import Any
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from sray.data_tools.atomic import atomic_write_bytes
from sray.data_tools.loader.class_stats import balanced_weights, count_pixels
from sray.data_tools.loader.augment import Augmentation
from sray.data_tools.loader.shard_loader import make_train_loader
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import Manifest, read_manifest
from sray.platform.eval.segmenter import Segmenter, SegmenterConfig, SegmenterRecord, save_segmenter

POOL_RULE = "each train scene's source pool: its train split minus its held-out test views"
"""The views the segmenter (and the probe) may read, as recorded with them."""

STATE_FILE = "training_state.pt"
"""Resumable state of an unfinished segmenter training, in its output folder."""

EPOCH_STEPS = 1000
"""Steps of one loader epoch: a resumable state is written at the end of each."""


def train_scene_names(manifest: Manifest, where: Path) -> tuple[list[str], list[str]]:
    """(train scene names, their one shared class list); ValueError naming the manifest otherwise."""
    names = sorted(s for s, e in manifest.scenes.items() if e.meta.get("role", "train") == "train")
    if not names:
        raise ValueError(f"{where}: no scene has role 'train'; the segmenter trains on train scenes only")
    classes = {tuple(manifest.scenes[s].meta["class_names"]) for s in names}
    if len(classes) != 1:
        raise ValueError(f"{where}: the train scenes use {len(classes)} label spaces; train on one label space")
    return names, list(classes.pop())


def pool_class_weights(shards: Path, manifest: Manifest, scenes: list[str], n_classes: int, mode: str) -> list[float]:
    """Class weights (``balanced_weights`` of ``mode``; [] for ``none``) from the scenes' source pools only."""
    if mode == "none":
        return []
    counts = np.zeros(n_classes + 1, np.int64)
    for scene in scenes:
        views = read_scene_views(shards, manifest.scenes[scene])
        pool = source_pool(SceneMeta.from_json(manifest.scenes[scene].meta))
        counts += count_pixels((views[v].label() for v in pool), n_classes)
    return balanced_weights(counts[:n_classes], mode)


def _read_state(out: Path, settings: dict[str, Any]) -> dict[str, Any] | None:
    """The resumable state in ``out`` or None; ValueError naming the file when its settings differ."""
    path = out / STATE_FILE
    if not path.exists():
        return None
    state = torch.load(path, map_location="cpu", weights_only=True)
    if state["settings"] != settings:
        differ = sorted(k for k in settings.keys() | state["settings"].keys()
                        if settings.get(k) != state["settings"].get(k))
        raise ValueError(f"{path}: an unfinished segmenter training with other settings ({', '.join(differ)}) is "
                         "stored here; resume it with its settings, or delete the file (or choose another --out) "
                         "to start this one")
    return state


def _write_state(out: Path, state: dict[str, Any]) -> None:
    """Write the resumable state atomically (a kill mid-write leaves the previous one)."""
    out.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    torch.save(state, buffer)
    atomic_write_bytes(out / STATE_FILE, buffer.getvalue())


def train_segmenter(shards: Path, cpu_seconds: float, out: Path, seed: int = 0, *,
                    augment: Augmentation | None = None, class_balance: str = "inverse-sqrt", n_source: int = 8,
                    top_k: int = 12, lr: float = 1e-3, feat_dim: int = 32, encoder_width: int = 16,
                    visit_samples: int = 1, cache_scenes: int = 4,
                    max_steps: int | None = None, progress: bool = True) -> SegmenterRecord:
    """Train a segmenter on ``shards``' train scenes for ``cpu_seconds`` into ``out``; its record. ``n_source`` images
    per step of ``top_k`` ranked neighbours; ``visit_samples``: steps per scene visit (1, interleaved, transfers better,
    docs/benchmarks.md "Ceilings"); ``cache_scenes``: decoded scenes kept; ``max_steps``: a cap; the rest: S-Ray's."""
    if cpu_seconds <= 0:
        raise ValueError(f"cpu_seconds is {cpu_seconds}; give the segmenter a positive CPU budget")
    shards = Path(shards)
    manifest = read_manifest(shards)
    scenes, class_names = train_scene_names(manifest, shards / "manifest.json")
    weights = pool_class_weights(shards, manifest, scenes, len(class_names), class_balance)
    settings = {"seed": seed, "shards": str(shards), "scenes": scenes, "views": POOL_RULE,
                "augmentation": dataclasses.asdict(augment or Augmentation()), "class_balance": class_balance,
                "class_names": class_names, "optimizer": f"Adam, constant lr {lr}", "n_source": n_source,
                "top_k": top_k, "visit_samples": visit_samples, "cache_scenes": cache_scenes, "feat_dim": feat_dim,
                "encoder_width": encoder_width}
    torch.manual_seed(seed)
    model = Segmenter(SegmenterConfig(n_classes=len(class_names), feat_dim=feat_dim, encoder_width=encoder_width,
                                      class_weights=tuple(weights)))
    model.train()
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    loader = make_train_loader(shards, n_source=n_source, top_k=top_k, rays_per_batch=1,
                               batches_per_epoch=EPOCH_STEPS, rank=0, world_size=1, num_workers=0, seed=seed,
                               scenes=scenes, augment=augment, source_labels=True, visit_samples=visit_samples,
                               cache_scenes=cache_scenes)
    out = Path(out)
    state = _read_state(out, settings)
    steps, images, spent_before, losses = 0, 0, 0.0, []
    if state is not None:
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        torch.set_rng_state(state["torch_rng"])
        loader.set_epoch(state["epoch"])
        steps, images, spent_before, losses = state["steps"], state["images"], state["cpu_seconds"], state["losses"]
        print(f"segmenter: resuming {out / STATE_FILE} at step {steps} ({spent_before:.0f} CPU s spent)")
    start = time.process_time() - spent_before  # process_time() - start: CPU seconds of every run together

    def done() -> bool:
        return time.process_time() - start >= cpu_seconds or (max_steps is not None and steps >= max_steps)

    bar = tqdm(total=round(cpu_seconds), initial=min(round(spent_before), round(cpu_seconds)), desc="segmenter",
               unit="CPU s", disable=not progress)
    while steps == 0 or not done():
        for sample in loader:
            loss = model.loss(sample.sources.rgb, sample.sources.label)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            steps, images = steps + 1, images + sample.sources.rgb.shape[0]
            losses = [*losses[-19:], float(loss.detach())]
            bar.update(min(round(time.process_time() - start), round(cpu_seconds)) - bar.n)
            if done():
                break
        else:  # a whole epoch: the loader's next one continues the stream after a resume
            _write_state(out, {"settings": settings, "epoch": loader.dataset.epoch, "steps": steps,
                               "images": images, "cpu_seconds": time.process_time() - start, "losses": losses,
                               "model": model.state_dict(), "optimizer": optimizer.state_dict(),
                               "torch_rng": torch.get_rng_state()})
    bar.close()
    spent = time.process_time() - start
    training = {"cpu_seconds_budget": cpu_seconds, "cpu_seconds": spent, "steps": steps, "images": images,
                "clock": "time.process_time of the training loop, data loading included (no loader workers), "
                         "summed over the runs of a resumed training",
                **settings, "final_loss": float(np.mean(losses))}
    save_segmenter(model.eval(), training, out)
    (out / STATE_FILE).unlink(missing_ok=True)
    return SegmenterRecord(model.cfg, training)
