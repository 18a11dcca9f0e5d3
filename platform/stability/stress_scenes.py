"""The unseen test scenes a stability suite stresses, read once; their perturbed copies (never the query views; one
generator per (seed, axis, scene) at every level); each query's sources, how much of it they see; the render watch."""

from __future__ import annotations

import dataclasses
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.samples import eval_sample, ranked_candidates
from sray.data_tools.loader.views import StoredView, read_scene_views
from sray.data_tools.png import encode_png
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import read_manifest
from sray.model.rendering import sample_uniform
from sray.model.reprojection import project, valid_projection
from sray.model.source_set import rigid_inverse
from sray.model.view_render import RayRenderer, strided_pixels
from sray.platform.common.model_input import ray_batch
from sray.platform.stability.axes import PointSpec, perturb_views


@dataclass
class StressScene:
    """One unseen test scene's stored views and metadata."""

    meta: SceneMeta
    views: dict[str, StoredView]

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
        scenes.append(StressScene(meta, read_scene_views(Path(shards), entry)))
    return scenes


def perturbed_views(scene: StressScene, ids: list[str], axis: str, level: float,
                    seed: int) -> dict[str, StoredView]:
    """The scene's views with those in ``ids`` perturbed on ``axis`` at ``level`` (the others shared)."""
    rgb = np.stack([scene.views[v].rgb() for v in ids])                      # (m, H, W, 3) uint8
    c2w = np.stack([scene.views[v].c2w for v in ids])                        # (m, 4, 4)
    rng = np.random.default_rng([seed, zlib.crc32(axis.encode()), zlib.crc32(scene.name.encode())])
    new_rgb, new_c2w = perturb_views(axis, level, rgb, c2w, rng)
    out = dict(scene.views)
    for i, v in enumerate(ids):
        out[v] = dataclasses.replace(scene.views[v], rgb_png=encode_png(new_rgb[i]), c2w=new_c2w[i])
    return out


def choose_sources(scene: StressScene, query_id: str, spec: PointSpec) -> list[str]:
    """The query's ranked neighbours ``drop .. drop + n_views`` in the spec's pool (the ``source`` split while it
    has enough views, else the whole source pool); ValueError names the scene, view and fix."""
    protocol = spec.pool == "protocol" and spec.n_views <= len(scene.source_ids)
    allowed = scene.source_ids if protocol else scene.pool_ids
    ranked = ranked_candidates(scene.views[query_id], set(allowed), len(allowed))
    chosen = ranked[spec.drop:spec.drop + spec.n_views]
    if len(chosen) < spec.n_views:
        raise ValueError(f"scene {scene.name!r}, view {query_id!r}: {len(ranked)} ranked source candidates, "
                         f"{spec.drop} dropped + {spec.n_views} needed; lower the level or re-shard with a larger "
                         "--neighbours")
    return chosen


def source_samples(scene: StressScene, views: dict[str, StoredView], spec: PointSpec) -> list[EvalSample]:
    """The evaluation sample of every held-out query, its sources chosen by ``spec`` and read from ``views``."""
    return [eval_sample(views, q, choose_sources(scene, q, spec), scene.name, scene.meta.near, scene.meta.far)
            for q in scene.test_ids]


@torch.no_grad()
def unseen_fraction(sample: EvalSample, stride: int, n_depths: int, min_depth: float) -> float:
    """The fraction of the query's coarse samples (``n_depths`` bin centres per ray, every ``stride``-th pixel) that
    project inside no source image (or lie behind every source camera): the ``unseen_rays`` axis's x."""
    h, w = sample.query_label.shape
    uv, _, _ = strided_pixels(h, w, stride)
    origins, dirs, near, far = ray_batch(sample, uv).query.rays()                   # (R, 3), (R, 3), (R,), (R,)
    z = sample_uniform(near, far, n_depths, stratified=False)                        # (R, N)
    points = origins[:, None, :].double() + z[..., None].double() * dirs[:, None, :].double()  # (R, N, 3)
    src = sample.sources
    uv_src, depth = project(points, src.K.double(), rigid_inverse(src.c2w.double()), min_depth)  # (m, R, N, 2)
    seen = valid_projection(uv_src, depth, tuple(src.rgb.shape[-2:]), min_depth).any(dim=0)     # (R, N)
    return float(1.0 - seen.double().mean())


class OutputWatch:
    """Wraps renderers: counts rays whose fine outputs hold NaN or +inf (all -inf logits are a miss, not a failure),
    and can poison them with NaN (the fault drill ``stability.nan_points``)."""

    def __init__(self, poison: bool) -> None:
        self.nonfinite_rays, self.poison = 0, poison

    def wrap(self, render: RayRenderer) -> RayRenderer:
        """The renderer, watched."""

        def watched(o: Tensor, d: Tensor, near: Tensor, far: Tensor) -> dict[str, dict[str, Tensor]]:
            out = render(o, d, near, far)
            fine = out["fine"]
            if self.poison:
                fine = {**fine, "logits": torch.full_like(fine["logits"], float("nan"))}
                out = {**out, "fine": fine}
            logits, rgb = fine["logits"], fine["rgb"]                                       # (R, L), (R, 3)
            bad = (torch.isnan(logits) | torch.isposinf(logits)).any(-1) | ~torch.isfinite(rgb).all(-1)  # (R,)
            self.nonfinite_rays += int(bad.sum())
            return out

        return watched
