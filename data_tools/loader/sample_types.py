"""The loader's sample types (docs/CONTRACTS.md "Loader samples"): one scene, no batch dimension.

One sample is one ray batch. How samples travel:

* the training DataLoader runs with ``batch_size=None``, so its collation is torch's
  ``default_convert``, which passes these dataclasses through unchanged (it converts only tensors,
  arrays, mappings and sequences);
* DataLoader workers send them to the main process pickled (the classes live at module level; torch
  moves their tensors through shared memory);
* with ``pin_memory=True`` the DataLoader calls each sample's :meth:`TensorFields.pin_memory`, after
  which ``sample.to(device, non_blocking=True)`` copies without making the host wait.

``near`` and ``far`` have one form outside the model: Python floats, the scene's z-depth bounds in
metres. They need no device move; the model surface (``sray.model.ray_batch.QueryRays.rays``) turns
them into per-ray (R,) tensors, once.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import TypeVar

import torch
from torch import Tensor

T = TypeVar("T", bound="TensorFields")


class TensorFields:
    """Device moves of a dataclass whose fields are tensors, nested :class:`TensorFields` or host values
    (strings, floats), which stay as they are."""

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
    """The m source views of a sample (ranked neighbours of its query view), full resolution."""

    rgb: Tensor
    """float32 (m, 3, H, W) colours in [0, 1]."""
    K: Tensor
    """float32 (m, 3, 3) intrinsics (pixel (u, v) centred at (u, v))."""
    c2w: Tensor
    """float32 (m, 4, 4) camera-to-world, OpenCV axes."""
    depth: Tensor | None = None
    """float32 (m, H, W) z-depth in metres, 0 = unknown, at the colours' size (the loader always fills it;
    the model reads it only with ``model.inputs='rgbd'``). A query view's depth is never a source input."""
    label: Tensor | None = None
    """int64 (m, H, W) class ids, ``IGNORE_ID`` (255) unlabelled, at the colours' size: filled only when the
    training loader is asked for source labels (the source-view semantic loss); evaluation never fills it."""


@dataclass(frozen=True)
class QueryCamera(TensorFields):
    """The camera of a sample's query view."""

    K: Tensor
    """float32 (3, 3) intrinsics."""
    c2w: Tensor
    """float32 (4, 4) camera-to-world, OpenCV axes."""


@dataclass(frozen=True)
class SceneQuery(TensorFields):
    """What every sample holds: which view of which scene, the cameras and the scene's bounds."""

    scene: str
    """Scene name (a key of the shard manifest)."""
    query_id: str
    """The query view's id within its scene."""
    sources: SourceViews
    """The source views the model sees."""
    query: QueryCamera
    """The query view's camera."""
    near: float
    """The scene's near z-depth bound in metres (its own, measured from its depth)."""
    far: float
    """The scene's far z-depth bound in metres."""


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
