"""The canonical scene: the one in-memory contract every reader produces and the shard writer consumes. Pixel (u, v)
is centred at (u, v) in K's coordinates (a centred principal point is ((W - 1) / 2, (H - 1) / 2));
poses are camera-to-world in OpenCV axes (x right, y down, z forward): readers convert once, nothing downstream."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field

import numpy as np

IGNORE_ID = 255
"""Label id of unlabelled pixels in every label space; never a prediction target."""

SPLIT_NAMES = ("train", "source", "finetune", "test")
"""Per-scene view splits: ``train`` in a training scene; in an unseen test scene the paper's protocol, ``source``
(fixed source views), ``finetune`` (extra views for per-scene finetuning), ``test`` (held out, only evaluated)."""


@dataclass
class View:
    """One posed, labelled frame of a scene: ``rgb`` uint8 (H, W, 3); ``depth`` float32 (H, W) metres, 0 = unknown;
    ``label`` uint16 (H, W) class ids, IGNORE_ID = unlabelled; ``K`` float64 (3, 3); ``c2w`` float64 (4, 4)."""

    view_id: str
    """Stable id, unique within the scene, without '.' (webdataset splits keys on dots)."""
    rgb: np.ndarray
    depth: np.ndarray
    label: np.ndarray
    K: np.ndarray
    c2w: np.ndarray

    @property
    def hw(self) -> tuple[int, int]:
        """Image height and width."""
        return int(self.rgb.shape[0]), int(self.rgb.shape[1])


@dataclass
class SceneMeta:
    """Everything about a scene except its pixels."""

    name: str
    """Scene name, unique in the dataset, without '.' or '/'."""
    label_space: str
    """Name of the label space, e.g. ``scannet20`` or ``nyu40``."""
    class_names: list[str]
    """Class names indexed by label id (ids 0 .. len-1)."""
    view_ids: list[str]
    """All view ids of the scene, in capture order."""
    splits: dict[str, list[str]]
    """View ids per split name (see :data:`SPLIT_NAMES`); views may be absent from every split."""
    near: float = 0.0
    """Near depth bound in metres (robust percentile with a margin); 0 = not yet measured."""
    far: float = 0.0
    """Far depth bound in metres; 0 = not yet measured."""
    role: str = "train"
    """``train`` (seen in pretraining) or ``test`` (unseen scene, evaluated with the protocol)."""
    ignore_id: int = IGNORE_ID
    labelled: bool = True
    """False: a capture without labels (all ``ignore_id``), for inference only (``sray label``); training refuses it."""
    extra: dict = field(default_factory=dict)
    """Free-form provenance (source format, dropped frames, generator seed, ...)."""

    def to_json(self) -> dict:
        """JSON-serialisable form (used by scene.json and the shard metadata)."""
        return {**asdict(self), "class_names": list(self.class_names), "view_ids": list(self.view_ids),
                "splits": {k: list(v) for k, v in self.splits.items()}, "near": float(self.near),
                "far": float(self.far), "ignore_id": int(self.ignore_id), "labelled": bool(self.labelled)}

    @classmethod
    def from_json(cls, d: dict) -> SceneMeta:
        """Inverse of :meth:`to_json`; raises KeyError naming a missing field."""
        return cls(name=d["name"], label_space=d["label_space"], class_names=list(d["class_names"]),
                   view_ids=list(d["view_ids"]), splits={k: list(v) for k, v in d["splits"].items()},
                   near=float(d.get("near", 0.0)), far=float(d.get("far", 0.0)), role=d.get("role", "train"),
                   ignore_id=int(d.get("ignore_id", IGNORE_ID)), labelled=bool(d.get("labelled", True)),
                   extra=dict(d.get("extra", {})))


@dataclass
class Scene:
    """A scene: its metadata plus lazy access to its views (large scans never sit in memory whole)."""

    meta: SceneMeta
    read_view: Callable[[str], View]
    """Loads one view by id."""

    def views(self) -> Iterator[View]:
        """Every view in ``meta.view_ids`` order, read lazily."""
        return map(self.read_view, self.meta.view_ids)

    @classmethod
    def in_memory(cls, meta: SceneMeta, views: list[View]) -> Scene:
        """A scene backed by a list of already-loaded views."""
        return cls(meta=meta, read_view={v.view_id: v for v in views}.__getitem__)


def source_pool(meta: SceneMeta) -> list[str]:
    """View ids that may serve as source views (and training queries), in capture order: a ``train`` scene's ``train``
    minus its held-out ``test``; a ``test`` scene's ``source`` plus ``finetune`` (never ``test``)."""
    if meta.role == "test":
        allowed = set(meta.splits.get("source", [])) | set(meta.splits.get("finetune", []))
        fix = "a test scene needs a non-empty 'source' split"
    else:
        allowed = set(meta.splits.get("train", [])) - set(meta.splits.get("test", []))
        fix = "a train scene needs a 'train' split with views outside its 'test' split"
    pool = [v for v in meta.view_ids if v in allowed]
    if not pool:
        raise ValueError(f"scene {meta.name!r}: field 'splits' gives no source views; {fix}")
    return pool


def depth_views(meta: SceneMeta) -> list[str]:
    """View ids whose depth may shape scene-wide quantities (near/far, the neighbours' fallback depth): every view
    of a ``train`` scene, the :func:`source_pool` of a ``test`` scene (its test views' depth is ground truth)."""
    return source_pool(meta) if meta.role == "test" else list(meta.view_ids)


def scene_depth_bounds(meta: SceneMeta, depth_of_view: Callable[[str], np.ndarray]) -> tuple[float, float]:
    """The scene's (near, far): :func:`depth_bounds` over the depth maps of :func:`depth_views`;
    ``depth_of_view(view_id)`` returns that view's float32 (H, W) depth in metres (any subsampling of it will do)."""
    views = depth_views(meta)
    try:
        return depth_bounds([depth_of_view(v) for v in views])
    except ValueError as e:
        where = "source and finetune views" if meta.role == "test" else "views"
        raise ValueError(f"scene {meta.name!r}: {e} (looked at its {len(views)} {where})") from None


def depth_bounds(depths: list[np.ndarray], lo_pct: float = 1.0, hi_pct: float = 99.0,
                 margin: float = 0.1) -> tuple[float, float]:
    """Near/far from valid depth: near = max(p_lo * (1 - margin), 0.05 m), far = p_hi * (1 + margin) with the
    ``lo_pct`` and ``hi_pct`` percentiles; ValueError when no pixel has a valid (> 0, finite) depth."""
    values = np.concatenate([d[(d > 0) & np.isfinite(d)].ravel() for d in depths] or [np.zeros(0)])
    if values.size == 0:
        raise ValueError("no valid depth (> 0, finite) in any view: near/far cannot be measured")
    lo, hi = np.percentile(values, [lo_pct, hi_pct])
    return max(float(lo) * (1.0 - margin), 0.05), float(hi) * (1.0 + margin)
