"""Assembling loader samples (:mod:`sray.data_tools.loader.sample_types`) from one scene's stored views."""

from __future__ import annotations

import numpy as np
import torch

from sray.data_tools.loader.augment import Augmentation, rescale_nearest, rescale_view
from sray.data_tools.loader.sample_types import EvalSample, QueryCamera, SourceViews, TrainSample
from sray.data_tools.loader.views import StoredView
from sray.data_tools.scene import IGNORE_ID


def ranked_candidates(query: StoredView, allowed: set[str], limit: int) -> list[str]:
    """The query's stored neighbours that are in ``allowed`` (never itself), best first, at most ``limit``."""
    return [v for v in query.neighbours.ids if v in allowed and v != query.view_id][:limit]


def _source_labels(views: list[StoredView], n_classes: int, scene: str, size_hw: tuple[int, int]) -> torch.Tensor:
    """int64 (m, H, W) source class ids (``IGNORE_ID`` unlabelled), checked, nearest-resized to ``size_hw``."""
    maps = []
    for view in views:
        label = view.label()
        check_label_ids(label, n_classes, scene, view.view_id)
        maps.append(rescale_nearest(label, size_hw))
    return torch.from_numpy(np.stack(maps).astype(np.int64))


def _sources(views: dict[str, StoredView], source_ids: list[str], augment: Augmentation | None = None,
             rng: np.random.Generator | None = None, labels: tuple[int, str] | None = None) -> SourceViews:
    """The source views' colours (m, 3, H, W) in [0, 1], depth (m, H, W) in metres and cameras; with ``labels`` =
    (n_classes, scene) also their class ids (m, H, W). ``augment`` jitters each image on its own and resizes all by
    one drawn factor (depth and labels by nearest pixel centre, never blended); it draws nothing when off."""
    sources = [views[s] for s in source_ids]
    scale = augment.scale(rng) if augment is not None else 1.0
    images, Ks, depths = [], [], []
    for view in sources:
        rgb = augment.jitter(view.rgb(), rng) if augment is not None else view.rgb()
        rgb, K = rescale_view(rgb, view.K, scale)
        images.append(rgb)
        Ks.append(K)
        depths.append(rescale_nearest(view.depth(), rgb.shape[:2]))
    rgb = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2)                      # (m, 3, H, W) uint8 view
    return SourceViews(rgb=torch.empty(rgb.shape, dtype=torch.float32).copy_(rgb).div_(255.0),  # one strided pass
                       K=torch.from_numpy(np.stack(Ks)).float(),
                       c2w=torch.from_numpy(np.stack([v.c2w for v in sources])).float(),
                       depth=torch.from_numpy(np.stack(depths)),                         # (m, H, W) float32
                       label=None if labels is None else _source_labels(sources, *labels, rgb.shape[-2:]))


def _query(view: StoredView) -> QueryCamera:
    """The query view's camera: K (3, 3), c2w (4, 4)."""
    return QueryCamera(K=torch.tensor(view.K, dtype=torch.float32), c2w=torch.tensor(view.c2w, dtype=torch.float32))


def check_label_ids(labels: np.ndarray, n_classes: int, scene: str, view_id: str) -> None:
    """Refuse label ids outside [0, n_classes) but ``IGNORE_ID``, on the host (the step never reads tensor values)."""
    bad = (labels != IGNORE_ID) & (labels >= n_classes)
    if bad.any():
        raise ValueError(f"scene {scene!r}, view {view_id!r}: label ids {sorted(set(labels[bad].tolist()))[:5]} lie "
                         f"outside the scene's {n_classes} classes (ignore id {IGNORE_ID}); fix the label space in "
                         "scene.json or re-convert the scene")


def train_sample(views: dict[str, StoredView], query_id: str, source_ids: list[str], n_rays: int,
                 rng: np.random.Generator, scene: str, near: float, far: float, n_classes: int,
                 augment: Augmentation | None = None, source_labels: bool = False) -> TrainSample:
    """A training sample: sources, query camera and ``n_rays`` query pixels drawn uniformly without replacement (with it
    only beyond the pixel count), targets checked against ``n_classes``; ``augment`` jitters and resizes the sources
    (None or all off: plain); ``source_labels`` adds their class ids (``SourceViews.label``)."""
    query = views[query_id]
    rgb, label = query.rgb(), query.label()                                           # (H, W, 3), (H, W)
    h, w = label.shape
    flat = rng.choice(h * w, size=n_rays, replace=n_rays > h * w)                     # (R,)
    v, u = np.divmod(flat, w)
    targets = label[v, u].astype(np.int64)                                            # (R,)
    check_label_ids(targets, n_classes, scene, query_id)
    sources = _sources(views, source_ids, augment, rng, (n_classes, scene) if source_labels else None)
    return TrainSample(
        scene=scene, query_id=query_id, sources=sources, query=_query(query),
        near=float(near), far=float(far),
        pixels=torch.from_numpy(np.stack([u, v], axis=1).astype(np.float32)),          # (R, 2)
        target_label=torch.from_numpy(targets),
        target_rgb=torch.from_numpy(rgb[v, u].astype(np.float32) / 255.0))            # (R, 3)


def eval_sample(views: dict[str, StoredView], query_id: str, source_ids: list[str], scene: str,
                near: float, far: float) -> EvalSample:
    """An evaluation sample: sources, query camera and the whole query image, labels and depth."""
    query = views[query_id]
    return EvalSample(
        scene=scene, query_id=query_id, sources=_sources(views, source_ids), query=_query(query),
        near=float(near), far=float(far),
        query_rgb=torch.from_numpy(query.rgb().astype(np.float32) / 255.0),             # (H, W, 3)
        query_label=torch.from_numpy(query.label().astype(np.int64)),                   # (H, W)
        query_depth=torch.from_numpy(query.depth()))                                    # (H, W) metres
