"""Per-class pixel counts of a dataset (scene folders or shards) and the class-frequency-aware loss weights."""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.png import decode_png
from sray.data_tools.scene import IGNORE_ID, SceneMeta, source_pool
from sray.data_tools.scene_folder import list_scenes
from sray.data_tools.shards.manifest import read_manifest

BALANCE_MODES = ("none", "inverse-sqrt", "inverse")
"""Class weighting of the semantic loss: none, w_c ∝ f_c^-1/2 or w_c ∝ f_c^-1 (f_c: pixel frequency)."""


def count_pixels(labels: Iterable[np.ndarray], n_classes: int) -> np.ndarray:
    """int64 (n_classes + 1,): pixels of each class id, then of the ignore id; other ids: ValueError (wrong space)."""
    counts = np.zeros(n_classes + 1, np.int64)
    for label in labels:
        flat = np.asarray(label).ravel().astype(np.int64)
        ignore = flat == IGNORE_ID
        if np.any(flat[~ignore] >= n_classes) or np.any(flat < 0):
            raise ValueError(f"label ids outside 0..{n_classes - 1} and {IGNORE_ID}: "
                             f"{sorted(set(flat[~ignore & (flat >= n_classes)].tolist()))[:5]}")
        counts[:n_classes] += np.bincount(flat[~ignore], minlength=n_classes)
        counts[n_classes] += int(ignore.sum())
    return counts


def _scene_counts(scenes: Iterable[tuple[str, list[str], Iterable[np.ndarray]]], missing: str
                  ) -> tuple[list[str], dict[str, np.ndarray]]:
    """(class names, {scene: counts}) of ``(scene, class names, labels read lazily)``; ValueError(missing) if none."""
    names: list[str] = []
    per_scene: dict[str, np.ndarray] = {}
    for scene, class_names, labels in scenes:
        names = names or list(class_names)
        per_scene[scene] = count_pixels(labels, len(names))
    if not per_scene:
        raise ValueError(missing)
    return names, per_scene


def dataset_pixel_counts(dataset_dir: Path, roles: tuple[str, ...] = ("train", "test")
                         ) -> tuple[list[str], dict[str, np.ndarray]]:
    """(class names, {scene: counts}) of every scene of ``roles`` in a dataset folder (sray layout)."""
    def scenes():
        for scene_dir in list_scenes(Path(dataset_dir)):
            meta = SceneMeta.from_json(json.loads((scene_dir / "scene.json").read_text()))
            if meta.role in roles:
                paths = [scene_dir / "label" / f"{v}.png" for v in meta.view_ids]
                yield meta.name, meta.class_names, (decode_png(p.read_bytes(), str(p)) for p in paths)
    return _scene_counts(scenes(), f"{dataset_dir}: no scene with role in {roles}; is it a dataset written by "
                                   "`sray data synth`?")


def shard_pixel_counts(shards_dir: Path, roles: tuple[str, ...] = ("train",)
                       ) -> tuple[list[str], dict[str, np.ndarray]]:
    """(class names, {scene: counts}) of every scene of ``roles`` in a shard folder, over the views the training
    loader reads (``scene.source_pool``), so class weights never read a held-out or test view's labels."""
    def scenes():
        for scene, entry in sorted(read_manifest(Path(shards_dir)).scenes.items()):
            if entry.meta.get("role", "train") in roles:
                views = read_scene_views(Path(shards_dir), entry)
                pool = source_pool(SceneMeta.from_json(entry.meta))
                yield scene, entry.meta["class_names"], (views[v].label() for v in pool)
    return _scene_counts(scenes(), f"{shards_dir}/manifest.json: no scene with role in {roles}")


def balanced_weights(counts: np.ndarray, mode: str, max_ratio: float = 10.0) -> list[float]:
    """Per-class loss weights (n_classes,) from pixel counts (n_classes,) of the labelled classes, by ``mode``
    (:data:`BALANCE_MODES`), clipped to ``max_ratio`` times the smallest and scaled so that sum_c f_c w_c = 1 (the
    loss keeps its scale); classes without pixels (never targets) get the largest weight."""
    if mode not in BALANCE_MODES:
        raise ValueError(f"class balance mode {mode!r}; use one of {BALANCE_MODES}")
    counts = np.asarray(counts, np.float64)
    if mode == "none" or counts.sum() <= 0:
        return [1.0] * len(counts)
    freq = counts / counts.sum()
    present = freq > 0
    w = np.zeros_like(freq)
    w[present] = freq[present] ** (-0.5 if mode == "inverse-sqrt" else -1.0)
    w[present] = np.minimum(w[present], max_ratio * w[present].min())
    w[~present] = w[present].max()
    w /= float(np.sum(freq * w))
    return [float(v) for v in w]
