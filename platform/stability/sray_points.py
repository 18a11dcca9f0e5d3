"""One point of the suite for an S-Ray model: its held-out views rendered from the sources a spec picks,
as ``sray eval`` renders them, and scored.

With no perturbation, ``n_source`` protocol sources, fp32 and the same stride, a point reproduces
``sray eval``'s dataset-level mIoU and PSNR exactly: the sources are the query's top-ranked
neighbours in the ``source`` split, each scene's views are rendered and scored by ``sray eval``'s loop
(:func:`~sray.platform.eval.scene_scoring.score_scene`, ``chunk``-ray passes, one confusion matrix per
scene) and scenes are averaged unweighted.
"""

from __future__ import annotations

import contextlib
from typing import Any

import torch
from torch import Tensor, nn

from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.samples import eval_sample, ranked_candidates
from sray.data_tools.loader.views import StoredView
from sray.model.rendering import sample_uniform
from sray.model.reprojection import project, valid_projection
from sray.model.source_set import SourceSet, rigid_inverse
from sray.model.view_render import RayRenderer, strided_pixels
from sray.platform.common.model_input import ray_batch
from sray.platform.eval.scene_scoring import score_scene
from sray.platform.eval.view_scoring import predict_view
from sray.platform.stability.point_spec import PointSpec
from sray.platform.stability.stress_scenes import StressScene, perturbed_views

AUTOCAST_DTYPES = {"bf16": torch.bfloat16, "fp16": torch.float16}
"""Inference precisions other than fp32, as autocast dtypes."""


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


class OutputWatch:
    """Wraps a renderer: counts rays whose fine outputs are not finite, and can poison them (a fault drill)."""

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
            bad = ~torch.isfinite(fine["logits"]).all(-1) | ~torch.isfinite(fine["rgb"]).all(-1)  # (R,)
            self.nonfinite_rays += int(bad.sum())
            return out

        return watched


def precision_context(precision: str, device: torch.device) -> contextlib.AbstractContextManager:
    """Autocast for ``precision`` (``fp32``: none); ValueError for fp16 off CUDA."""
    if precision == "fp32":
        return contextlib.nullcontext()
    if precision == "fp16" and device.type != "cuda":
        raise ValueError("precision fp16 needs a CUDA device (CPU autocast runs bf16)")
    return torch.autocast(device.type, dtype=AUTOCAST_DTYPES[precision])


@torch.no_grad()
def encoded_pool(net: nn.Module, views: dict[str, StoredView], ids: list[str], scene: StressScene,
                 device: torch.device) -> SourceSet:
    """Every source a point's queries use, encoded once (each query then takes its ranked subset)."""
    sources = eval_sample(views, scene.test_ids[0], ids, scene.name, scene.meta.near, scene.meta.far).sources
    sources = sources.to(device)
    return net.encode(sources.rgb, sources.K, sources.c2w, sources.depth)


def bound_renderer(net: nn.Module, pool: SourceSet, index: list[int]) -> RayRenderer:
    """A deterministic ray renderer of ``net`` from the pool's views at ``index``, in that order."""
    return net.ray_renderer(pool.select(index))


def sray_point(net: nn.Module, scenes: list[StressScene], spec: PointSpec, stride: int, chunk: int,
               device: torch.device, poison: bool = False) -> dict[str, Any]:
    """Score ``net`` at ``spec`` on ``scenes``: mean dataset-level mIoU and PSNR, per-scene scores, the measured
    unseen fraction, non-finite rays and (below fp32) argmax agreement with the fp32 render.

    The sources of all of a scene's queries are encoded once per point (an image's features do not depend on
    the other images of its batch), and each query renders from its ranked subset of them.
    """
    n_classes, ignore_id = net.cfg.n_classes, net.cfg.ignore_id
    watch = OutputWatch(poison)
    per_scene, unseen, agree, total = {}, [], 0, 0
    for scene in scenes:
        plan = {q: choose_sources(scene, q, spec) for q in scene.test_ids}
        ids = sorted({s for chosen in plan.values() for s in chosen})
        views = scene.views if spec.perturbation is None else perturbed_views(scene, ids, *spec.perturbation, spec.seed)
        with precision_context(spec.precision, device):
            pool = encoded_pool(net, views, ids, scene, device)
        reference = encoded_pool(net, views, ids, scene, device) if spec.precision != "fp32" else None
        samples = [eval_sample(views, q, chosen, scene.name, scene.meta.near, scene.meta.far)
                   for q, chosen in plan.items()]
        index = {q: [ids.index(s) for s in chosen] for q, chosen in plan.items()}
        with precision_context(spec.precision, device):
            scored = score_scene(lambda s: watch.wrap(bound_renderer(net, pool, index[s.query_id])), samples,
                                 n_classes, ignore_id, stride, chunk, device)
        for sample, view in zip(samples, scored.views):
            if reference is not None:
                fp32 = predict_view(bound_renderer(net, reference, index[sample.query_id]), sample, stride, chunk,
                                    device)
                agree += int((fp32.pred_label == view.pred_label).sum())
                total += fp32.pred_label.numel()
            unseen.append(unseen_fraction(sample, stride, net.cfg.n_coarse, net.cfg.min_source_depth))
        per_scene[scene.name] = {"miou": scored.scores["miou"], "psnr": scored.scores["psnr"]}
    return {"miou": sum(s["miou"] for s in per_scene.values()) / len(per_scene),
            "psnr": sum(s["psnr"] for s in per_scene.values()) / len(per_scene),
            "unseen_fraction": sum(unseen) / len(unseen), "nonfinite_rays": watch.nonfinite_rays,
            "fp32_agreement": agree / total if total else None, "scenes": per_scene}
