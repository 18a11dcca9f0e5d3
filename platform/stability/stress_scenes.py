"""The unseen test scenes a stability suite stresses, read once, and their perturbed copies.

A perturbation replaces the stored views it touches by new :class:`StoredView` objects (colour
re-encoded as lossless PNG, camera replaced); the query views a method is scored on are never
perturbed, so every level is scored against the same ground truth. Perturbations are drawn with
common random numbers: the generator of a (seed, axis, scene) is the same at every level, so a
level differs from the next only by its magnitude (pose noise turns about the same axes, occluders
sit at the same places), which keeps the curves free of level-to-level sampling noise.
"""

from __future__ import annotations

import dataclasses
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sray.data_tools.loader.views import StoredView, read_scene_views
from sray.data_tools.png import encode_png
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import read_manifest
from sray.platform.stability.axes import perturb_views


@dataclass
class StressScene:
    """One unseen test scene's stored views and metadata."""

    meta: SceneMeta
    views: dict[str, StoredView]
    image_size: tuple[int, int]
    """(H, W) of its views."""

    @property
    def name(self) -> str:
        """The scene's name in the shard manifest."""
        return self.meta.name

    @property
    def test_ids(self) -> list[str]:
        """The held-out query views every method is scored on."""
        return list(self.meta.splits["test"])

    @property
    def source_ids(self) -> list[str]:
        """The protocol's source split (the fixed sources of ``sray eval``)."""
        return list(self.meta.splits["source"])

    @property
    def pool_ids(self) -> list[str]:
        """Every view a method may see: ``source`` + ``finetune`` (Semantic-NeRF's training views)."""
        return source_pool(self.meta)


def load_scenes(shards: Path, names: list[str]) -> list[StressScene]:
    """Read the named test scenes out of ``shards``; ValueError names the manifest and the fix."""
    manifest = read_manifest(Path(shards))
    scenes = []
    for name in names:
        if name not in manifest.scenes:
            raise ValueError(f"{shards}/manifest.json: no scene {name!r}; known: {sorted(manifest.scenes)[:10]}")
        entry = manifest.scenes[name]
        meta = SceneMeta.from_json(entry.meta)
        if meta.role != "test" or not meta.splits.get("test") or not meta.splits.get("source"):
            raise ValueError(f"{shards}/manifest.json: scene {name!r} is not an unseen test scene with 'source' and "
                             "'test' splits; pass test scenes (role 'test') to the stability suite")
        scenes.append(StressScene(meta, read_scene_views(Path(shards), entry), tuple(entry.image_size)))
    return scenes


def perturbation_rng(seed: int, axis: str, scene: str) -> np.random.Generator:
    """The generator of one (seed, axis, scene): the same at every level of the axis."""
    return np.random.default_rng([seed, zlib.crc32(axis.encode()), zlib.crc32(scene.encode())])


def perturbed_views(scene: StressScene, ids: list[str], axis: str, level: float,
                    seed: int) -> dict[str, StoredView]:
    """The scene's views with those in ``ids`` perturbed on ``axis`` at ``level`` (the others shared)."""
    rgb = np.stack([scene.views[v].rgb() for v in ids])                      # (m, H, W, 3) uint8
    c2w = np.stack([scene.views[v].c2w for v in ids])                        # (m, 4, 4)
    new_rgb, new_c2w = perturb_views(axis, level, rgb, c2w, perturbation_rng(seed, axis, scene.name))
    out = dict(scene.views)
    for i, v in enumerate(ids):
        out[v] = dataclasses.replace(scene.views[v], rgb_png=encode_png(new_rgb[i]), c2w=new_c2w[i])
    return out
