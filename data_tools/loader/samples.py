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


def _cameras(views: list[StoredView]) -> tuple[torch.Tensor, torch.Tensor]:
    """K (m, 3, 3) and c2w (m, 4, 4) as float32 tensors."""
    K = torch.from_numpy(np.stack([v.K for v in views])).float()
    c2w = torch.from_numpy(np.stack([v.c2w for v in views])).float()
    return K, c2w


def _source_labels(views: list[StoredView], n_classes: int, scene: str,
                   size_hw: tuple[int, int] | None = None) -> torch.Tensor:
    """int64 (m, H, W) class ids of the source views (``IGNORE_ID`` unlabelled), checked against ``n_classes``;
    resized to ``size_hw`` by nearest pixel centre (:func:`rescale_nearest`) when given."""
    maps = []
    for view in views:
        label = view.label()
        check_label_ids(label, n_classes, scene, view.view_id)
        maps.append(label if size_hw is None else rescale_nearest(label, size_hw))
    return torch.from_numpy(np.stack(maps).astype(np.int64))


def _sources(views: dict[str, StoredView], source_ids: list[str], labels: tuple[int, str] | None = None) -> SourceViews:
    """The source views' colours (m, 3, H, W) in [0, 1], depth (m, H, W) in metres and cameras; with
    ``labels`` = (n_classes, scene) also their class ids (m, H, W)."""
    sources = [views[s] for s in source_ids]
    rgb = torch.from_numpy(np.stack([v.rgb() for v in sources])).permute(0, 3, 1, 2)  # (m, 3, H, W) uint8 view
    src_rgb = torch.empty(rgb.shape, dtype=torch.float32).copy_(rgb).div_(255.0)       # one strided pass
    K, c2w = _cameras(sources)
    depth = torch.from_numpy(np.stack([v.depth() for v in sources]))                  # (m, H, W) float32
    label = None if labels is None else _source_labels(sources, *labels)
    return SourceViews(rgb=src_rgb, K=K, c2w=c2w, depth=depth, label=label)


def _augmented_sources(views: dict[str, StoredView], source_ids: list[str], augment: Augmentation,
                       rng: np.random.Generator, labels: tuple[int, str] | None = None) -> SourceViews:
    """Like :func:`_sources`, each image jittered on its own and all resized by one drawn factor (depth and
    labels by nearest pixel centre, never blended: :func:`~sray.data_tools.loader.augment.rescale_nearest`)."""
    scale = augment.scale(rng)
    images, Ks, depths = [], [], []
    for s in source_ids:
        rgb, K = rescale_view(augment.jitter(views[s].rgb(), rng), views[s].K, scale)
        images.append(rgb)
        Ks.append(K)
        depths.append(rescale_nearest(views[s].depth(), rgb.shape[:2]))
    rgb = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2)                      # (m, 3, H', W') uint8
    c2w = torch.from_numpy(np.stack([views[s].c2w for s in source_ids])).float()
    label = None if labels is None else _source_labels([views[s] for s in source_ids], *labels, rgb.shape[-2:])
    return SourceViews(rgb=rgb.float().div_(255.0), K=torch.from_numpy(np.stack(Ks)).float(), c2w=c2w,
                       depth=torch.from_numpy(np.stack(depths)), label=label)


def _query(view: StoredView) -> QueryCamera:
    """The query view's camera: K (3, 3), c2w (4, 4)."""
    K, c2w = _cameras([view])
    return QueryCamera(K=K[0], c2w=c2w[0])


def check_label_ids(labels: np.ndarray, n_classes: int, scene: str, view_id: str) -> None:
    """Refuse label ids outside [0, n_classes) other than ``IGNORE_ID`` (checked here, on the host,
    once per batch, so the training step never reads tensor values to check them)."""
    bad = (labels != IGNORE_ID) & (labels >= n_classes)
    if bad.any():
        raise ValueError(f"scene {scene!r}, view {view_id!r}: label ids {sorted(set(labels[bad].tolist()))[:5]} lie "
                         f"outside the scene's {n_classes} classes (ignore id {IGNORE_ID}); fix the label space in "
                         "scene.json or re-convert the scene")


def train_sample(views: dict[str, StoredView], query_id: str, source_ids: list[str], n_rays: int,
                 rng: np.random.Generator, scene: str, near: float, far: float, n_classes: int,
                 augment: Augmentation | None = None, source_labels: bool = False) -> TrainSample:
    """A training sample: sources, query camera and ``n_rays`` random pixels of the query with targets.

    Pixels are drawn without replacement (with replacement only when ``n_rays`` exceeds the pixel
    count), uniformly over the image; ``pixels`` (R, 2) holds integer (u, v) pixel centres as float32. Target
    label ids are checked against the scene's ``n_classes`` (:func:`check_label_ids`). ``augment``
    (:mod:`.augment`) jitters and resizes the sources; None, or every option off, gives the plain sample.
    ``source_labels`` also delivers the source views' class ids (``SourceViews.label``, for the source-view
    semantic loss).
    """
    query = views[query_id]
    rgb, label = query.rgb(), query.label()                                           # (H, W, 3), (H, W)
    h, w = label.shape
    flat = rng.choice(h * w, size=n_rays, replace=n_rays > h * w)                     # (R,)
    v, u = np.divmod(flat, w)
    targets = label[v, u].astype(np.int64)                                            # (R,)
    check_label_ids(targets, n_classes, scene, query_id)
    plain = augment is None or (not augment.jitters_colour and augment.source_scale <= 0)
    labels = (n_classes, scene) if source_labels else None
    sources = (_sources(views, source_ids, labels) if plain
               else _augmented_sources(views, source_ids, augment, rng, labels))
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
