"""Which source views a point renders each held-out query from, and how much of the query they see.

A spec (:class:`~sray.platform.stability.point_spec.PointSpec`) picks each query's sources among its ranked
neighbours (:func:`choose_sources`); with no perturbation, ``n_source`` protocol sources are exactly the ones ``sray
eval`` takes. :func:`unseen_fraction` measures what the ``unseen_rays`` axis charts: the share of the query's coarse
samples that project into no source image.
"""

from __future__ import annotations

import torch

from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.samples import eval_sample, ranked_candidates
from sray.data_tools.loader.views import StoredView
from sray.model.rendering import sample_uniform
from sray.model.reprojection import project, valid_projection
from sray.model.source_set import rigid_inverse
from sray.model.view_render import strided_pixels
from sray.platform.common.model_input import ray_batch
from sray.platform.stability.point_spec import PointSpec
from sray.platform.stability.stress_scenes import StressScene


def choose_sources(scene: StressScene, query_id: str, spec: PointSpec) -> list[str]:
    """The query's ranked neighbours ``drop .. drop + n_views`` in the spec's pool (the ``source`` split
    while it has enough views, else the whole source pool); ValueError names the scene, view and fix."""
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
    """The evaluation sample of every held-out query, its sources chosen by ``spec`` and read from ``views`` (the
    scene's views, some of its source pool perhaps perturbed: never a held-out query view)."""
    return [eval_sample(views, q, choose_sources(scene, q, spec), scene.name, scene.meta.near, scene.meta.far)
            for q in scene.test_ids]


@torch.no_grad()
def unseen_fraction(sample: EvalSample, stride: int, n_depths: int, min_depth: float) -> float:
    """Fraction of the query's deterministic coarse samples (``n_depths`` bin centres per ray, every
    ``stride``-th pixel) that project inside no source image (or lie behind every source camera)."""
    h, w = sample.query_label.shape
    uv, _, _ = strided_pixels(h, w, stride)
    origins, dirs, near, far = ray_batch(sample, uv).query.rays()                   # (R, 3), (R, 3), (R,), (R,)
    z = sample_uniform(near, far, n_depths, stratified=False)                        # (R, N)
    points = origins[:, None, :].double() + z[..., None].double() * dirs[:, None, :].double()  # (R, N, 3)
    src = sample.sources
    uv_src, depth = project(points, src.K.double(), rigid_inverse(src.c2w.double()), min_depth)  # (m, R, N, 2)
    seen = valid_projection(uv_src, depth, tuple(src.rgb.shape[-2:]), min_depth).any(dim=0)     # (R, N)
    return float(1.0 - seen.double().mean())
