"""Reading one scene's views out of its shards into memory, and decoding them without loss.

A loader worker keeps the ENCODED views of at most a few scenes (:class:`SceneCache`, least
recently used first out) and decodes only the images a sample needs, so memory stays near the
scenes' PNG bytes on disk (about 0.1-0.2 MB per 320x240 view) whatever the dataset size.
"""

from __future__ import annotations

import json
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import webdataset as wds

from sray.data_tools.png import decode_png, png16_to_depth
from sray.data_tools.shards.manifest import SceneEntry
from sray.data_tools.shards.neighbours import Neighbours
from sray.data_tools.shards.writer import KEY_SEPARATOR

REQUIRED = ("rgb.png", "depth.png", "label.png", "camera.json", "neighbours.json")


@dataclass
class StoredView:
    """One view as stored in a shard: encoded images, camera and ranked neighbours."""

    view_id: str
    """The view's id within its scene."""
    rgb_png: bytes
    """8-bit RGB PNG."""
    depth_png: bytes
    """16-bit depth PNG in millimetres."""
    label_png: bytes
    """16-bit label PNG."""
    K: np.ndarray
    """float64 (3, 3) intrinsics."""
    c2w: np.ndarray
    """float64 (4, 4) camera-to-world, OpenCV axes."""
    neighbours: Neighbours
    """Ranked source-view candidates."""
    where: str
    """``shard:key`` for error messages."""

    def rgb(self) -> np.ndarray:
        """uint8 (H, W, 3) RGB."""
        return decode_png(self.rgb_png, f"{self.where}.rgb.png")

    def label(self) -> np.ndarray:
        """uint16 (H, W) class ids (16-bit decoded without loss)."""
        label = decode_png(self.label_png, f"{self.where}.label.png")
        if label.dtype != np.uint16 or label.ndim != 2:
            raise ValueError(f"{self.where}.label.png: expected a 16-bit single-channel PNG, got {label.dtype} "
                             f"{label.shape}; re-run `sray data shard`")
        return label

    def depth(self) -> np.ndarray:
        """float32 (H, W) metres, 0 = unknown (16-bit millimetres decoded without loss)."""
        depth = decode_png(self.depth_png, f"{self.where}.depth.png")
        if depth.dtype != np.uint16 or depth.ndim != 2:
            raise ValueError(f"{self.where}.depth.png: expected a 16-bit single-channel PNG, got {depth.dtype} "
                             f"{depth.shape}; re-run `sray data shard`")
        return png16_to_depth(depth)


def _stored_view(sample: dict, view_id: str, where: str) -> StoredView:
    """Build a :class:`StoredView` from one webdataset sample dict (bytes per member suffix)."""
    missing = [c for c in REQUIRED if c not in sample]
    if missing:
        raise ValueError(f"{where}: members {missing} are missing; re-run `sray data shard`")
    camera = json.loads(sample["camera.json"])
    return StoredView(view_id=view_id, rgb_png=sample["rgb.png"], depth_png=sample["depth.png"],
                      label_png=sample["label.png"], K=np.asarray(camera["K"], np.float64),
                      c2w=np.asarray(camera["c2w"], np.float64),
                      neighbours=Neighbours.from_json(json.loads(sample["neighbours.json"])), where=where)


def read_scene_views(shards_dir: Path, entry: SceneEntry) -> dict[str, StoredView]:
    """Stream every shard of one scene and return its views by id (errors name the shard)."""
    scene = entry.meta["name"]
    prefix = f"{scene}{KEY_SEPARATOR}"
    views: dict[str, StoredView] = {}
    for shard in entry.shards:
        url = str(Path(shards_dir) / shard)
        for sample in wds.tarfile_samples([{"url": url}]):
            key = sample["__key__"]
            if not key.startswith(prefix):
                raise ValueError(f"{url}: sample {key!r} is not a view of scene {scene!r}; re-run `sray data shard`")
            view_id = key[len(prefix):]
            views[view_id] = _stored_view(sample, view_id, f"{url}:{key}")
    missing = [v for v in entry.meta["view_ids"] if v not in views]
    if missing:
        raise ValueError(f"{entry.shards}: views {missing[:5]} of scene {scene!r} are missing from its shards; "
                         "re-run `sray data shard` and `sray data shard --verify`")
    return views


class SceneCache:
    """Least-recently-used cache of at most ``capacity`` scenes' encoded views (one per loader worker)."""

    def __init__(self, capacity: int, load: Callable[[str], dict[str, StoredView]]) -> None:
        if capacity < 1:
            raise ValueError(f"cache capacity must be >= 1 scene, got {capacity}")
        self.capacity, self.load = capacity, load
        self._scenes: OrderedDict[str, dict[str, StoredView]] = OrderedDict()
        self.loads = 0
        """How many times a scene was read from its shards (for tests and benchmarks)."""

    def get(self, scene: str) -> dict[str, StoredView]:
        """The scene's views, reading its shards on a miss and evicting the least recently used."""
        if scene in self._scenes:
            self._scenes.move_to_end(scene)
            return self._scenes[scene]
        while len(self._scenes) >= self.capacity:
            self._scenes.popitem(last=False)
        views = self._scenes[scene] = self.load(scene)
        self.loads += 1
        return views

    def __len__(self) -> int:
        """Scenes currently cached."""
        return len(self._scenes)
