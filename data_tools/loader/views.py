"""Reading one scene's views out of its shards into memory, and decoding them without loss. A loader worker keeps
the ENCODED views of at most a few scenes (an LRU cache) and decodes only the images a sample needs, so memory
stays near the scenes' PNG bytes whatever the dataset."""

from __future__ import annotations

import json
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
    """One view as stored in a shard: encoded PNGs (8-bit RGB, 16-bit depth in millimetres, 16-bit labels), float64
    K (3, 3) and c2w (4, 4, OpenCV axes), ranked neighbours, and ``shard:key`` for error messages."""

    view_id: str
    rgb_png: bytes
    depth_png: bytes
    label_png: bytes
    K: np.ndarray
    c2w: np.ndarray
    neighbours: Neighbours
    where: str

    def rgb(self) -> np.ndarray:
        """uint8 (H, W, 3) RGB."""
        return decode_png(self.rgb_png, f"{self.where}.rgb.png")

    def label(self) -> np.ndarray:
        """uint16 (H, W) class ids."""
        return self._png16(self.label_png, "label")

    def depth(self) -> np.ndarray:
        """float32 (H, W) metres, 0 = unknown."""
        return png16_to_depth(self._png16(self.depth_png, "depth"))

    def _png16(self, data: bytes, member: str) -> np.ndarray:
        """A 16-bit single-channel PNG decoded without loss."""
        image = decode_png(data, f"{self.where}.{member}.png")
        if image.dtype != np.uint16 or image.ndim != 2:
            raise ValueError(f"{self.where}.{member}.png: expected a 16-bit single-channel PNG, got {image.dtype} "
                             f"{image.shape}; re-run `sray data shard`")
        return image


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
            missing = [c for c in REQUIRED if c not in sample]
            if missing:
                raise ValueError(f"{url}:{key}: members {missing} are missing; re-run `sray data shard`")
            camera, view_id = json.loads(sample["camera.json"]), key[len(prefix):]
            views[view_id] = StoredView(view_id, sample["rgb.png"], sample["depth.png"], sample["label.png"],
                                        np.asarray(camera["K"], np.float64), np.asarray(camera["c2w"], np.float64),
                                        Neighbours.from_json(json.loads(sample["neighbours.json"])), f"{url}:{key}")
    missing = [v for v in entry.meta["view_ids"] if v not in views]
    if missing:
        raise ValueError(f"{entry.shards}: views {missing[:5]} of scene {scene!r} are missing from its shards; "
                         "re-run `sray data shard` and `sray data shard --verify`")
    return views
