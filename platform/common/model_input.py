"""The one conversion from a loader sample to the model's input (the model cannot import the loader's types)."""

from __future__ import annotations

from torch import Tensor

from sray.data_tools.loader.sample_types import SceneQuery, TrainSample
from sray.model.ray_batch import QueryRays, RayBatch


def ray_batch(sample: SceneQuery, pixels: Tensor | None = None) -> RayBatch:
    """The model input of ``sample``: its sources (with their depth and labels), query camera and bounds, and the
    rays through ``pixels``: float32 (R, 2) (u, v), None = a training sample's own. The query's depth never enters."""
    if pixels is None:
        if not isinstance(sample, TrainSample):
            raise ValueError(f"scene {sample.scene!r}, view {sample.query_id!r}: a {type(sample).__name__} has no "
                             "pixels; pass the (R, 2) pixels to render")
        pixels = sample.pixels
    query = QueryRays(K=sample.query.K, c2w=sample.query.c2w, pixels=pixels, near=sample.near, far=sample.far)
    return RayBatch(src_rgb=sample.sources.rgb, src_K=sample.sources.K, src_c2w=sample.sources.c2w, query=query,
                    src_depth=sample.sources.depth, src_label=sample.sources.label)
