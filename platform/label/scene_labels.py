"""``sray label`` for one scene: every frame labelled by :meth:`Labeller.label`, written atomically as ``label/``,
``overlay/``, ``confidence/``, ``depth/`` PNGs and ``labels.json`` (docs/capture.md); scores are dataset-level and
fair, each frame being rendered from its other frames."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from sray.data_tools.atomic import atomic_write_bytes, atomic_write_json
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.png import depth_to_png16, encode_png
from sray.data_tools.scene import SceneMeta
from sray.data_tools.shards.manifest import Manifest
from sray.model.metrics import DATASET_PROTOCOL, confusion_matrix, scene_metrics
from sray.platform.label.labeller import Labeller, Labels
from sray.platform.viz.palette import colorize

LABELS_FILE = "labels.json"


def overlay(rgb: np.ndarray, label: np.ndarray, n_classes: int) -> np.ndarray:
    """uint8 (H, W, 3): the frame ``rgb`` (H, W, 3) and the colours of ``label`` (H, W), half and half."""
    return ((rgb.astype(np.uint16) + colorize(label, n_classes)) // 2).astype(np.uint8)


def write_frame_files(out_dir: Path, view_id: str, rgb: np.ndarray, labels: Labels, i: int, n_classes: int) -> None:
    """Frame ``i``'s PNGs: uint8 class ids, frame/label blend, 16-bit confidence x 65535 and depth in mm."""
    conf = np.round(np.clip(labels.confidence[i], 0, 1) * 65535).astype(np.uint16)
    for sub, image in (("label", labels.label[i]), ("overlay", overlay(rgb, labels.label[i], n_classes)),
                       ("confidence", conf), ("depth", depth_to_png16(labels.depth[i]))):
        atomic_write_bytes(Path(out_dir) / sub / f"{view_id}.png", encode_png(image))


def label_scene(labeller: Labeller, shards: Path, manifest: Manifest, scene: str, out_dir: Path,
                on_frame: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Label every view of ``scene`` (module doc) into ``out_dir``; returns what labels.json holds."""
    entry = manifest.scenes[scene]
    meta = SceneMeta.from_json(entry.meta)
    if len(meta.class_names) != labeller.n_classes:
        raise ValueError(f"{Path(shards) / 'manifest.json'}: scene {scene!r} has {len(meta.class_names)} classes, the "
                         f"model predicts {labeller.n_classes}; label data of the model's label space")
    views = read_scene_views(Path(shards), entry)
    ids = list(meta.view_ids)
    images = np.stack([views[v].rgb() for v in ids])
    poses, Ks = np.stack([views[v].c2w for v in ids]), np.stack([views[v].K for v in ids])
    labels = labeller.label(images, poses, Ks, depth_range=(meta.near, meta.far), on_frame=on_frame)
    for i, view_id in enumerate(ids):
        write_frame_files(out_dir, view_id, images[i], labels, i, labeller.n_classes)
    record: dict[str, Any] = {
        "scene": scene, "labelled": meta.labelled, "near": meta.near, "far": meta.far, "model": labeller.about,
        "n_source": labeller.n_source, "render": "fast" if labeller.fast is not None else "full",
        "class_names": meta.class_names,
        "frames": [{"view_id": v, "source_ids": [ids[j] for j in labels.sources[i]]} for i, v in enumerate(ids)]}
    if meta.labelled:
        conf = sum(confusion_matrix(torch.from_numpy(labels.label[i].astype(np.int64)),
                                    torch.from_numpy(views[v].label().astype(np.int64)), labeller.n_classes,
                                    meta.ignore_id) for i, v in enumerate(ids))
        record["scores"] = {"protocol": DATASET_PROTOCOL, **scene_metrics(conf)}
    atomic_write_json(Path(out_dir) / LABELS_FILE, record)
    return record
