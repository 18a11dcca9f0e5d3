"""The loader's sample types (docs/CONTRACTS.md "Loader samples", how they travel): one scene, one ray batch, no
batch dimension; ``near`` and ``far`` stay Python floats (z-depth bounds in metres) up to the model."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import TypeVar

import torch
from torch import Tensor

T = TypeVar("T", bound="TensorFields")


class TensorFields:
    """Device moves of a dataclass of tensors, nested :class:`TensorFields` and host values (left as they are)."""

    def _map(self: T, fn: Callable[[Tensor], Tensor]) -> T:
        """A copy with ``fn`` applied to every tensor field, nested ones included."""
        changes = {}
        for f in fields(self):  # subclasses are dataclasses
            value = getattr(self, f.name)
            if isinstance(value, Tensor):
                changes[f.name] = fn(value)
            elif isinstance(value, TensorFields):
                changes[f.name] = value._map(fn)
        return replace(self, **changes)

    def to(self: T, device: torch.device | str, non_blocking: bool = False) -> T:
        """A copy with every tensor on ``device`` (``non_blocking`` pays off from pinned memory)."""
        return self._map(lambda t: t.to(device, non_blocking=non_blocking))

    def pin_memory(self: T) -> T:
        """A copy with every tensor in page-locked host memory (what ``DataLoader(pin_memory=True)`` calls)."""
        return self._map(lambda t: t.pin_memory())


@dataclass(frozen=True)
class SourceViews(TensorFields):
    """The m source views of a sample (ranked neighbours of its query view): ``rgb`` float32 (m, 3, H, W) in [0, 1],
    ``K`` float32 (m, 3, 3) (pixel (u, v) centred at (u, v)), ``c2w`` float32 (m, 4, 4) OpenCV axes."""

    rgb: Tensor
    K: Tensor
    c2w: Tensor
    depth: Tensor | None = None
    """float32 (m, H, W) z-depth in metres, 0 = unknown (always filled; read with ``model.inputs='rgbd'``)."""
    label: Tensor | None = None
    """int64 (m, H, W) class ids, ``IGNORE_ID`` unlabelled: only for a training loader asked for source labels."""


@dataclass(frozen=True)
class QueryCamera(TensorFields):
    """The camera of a sample's query view: ``K`` float32 (3, 3), ``c2w`` float32 (4, 4) OpenCV axes."""

    K: Tensor
    c2w: Tensor


@dataclass(frozen=True)
class SceneQuery(TensorFields):
    """What every sample holds: scene (a manifest key) and query view, sources, query camera, z-depth bounds (m)."""

    scene: str
    query_id: str
    sources: SourceViews
    query: QueryCamera
    near: float
    far: float


@dataclass(frozen=True)
class TrainSample(SceneQuery):
    """A training sample: R random pixels of the query view with their targets."""

    pixels: Tensor
    """float32 (R, 2) integer (u, v) pixel centres of the sampled rays in the query image."""
    target_label: Tensor
    """int64 (R,) class ids, ``IGNORE_ID`` (255) for unlabelled pixels."""
    target_rgb: Tensor
    """float32 (R, 3) colours in [0, 1]."""


@dataclass(frozen=True)
class EvalSample(SceneQuery):
    """An evaluation sample: the whole query image with its ground truth (no pixels are drawn)."""

    query_rgb: Tensor
    """float32 (H, W, 3) colours in [0, 1]."""
    query_label: Tensor
    """int64 (H, W) class ids, ``IGNORE_ID`` (255) for unlabelled pixels."""
    query_depth: Tensor
    """float32 (H, W) z-depth in metres, 0 = unknown."""
