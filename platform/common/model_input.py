"""The one conversion from a loader sample (``sray.data_tools``) to the model's input (``sray.model``).

The model cannot import the loader's types (ARCHITECTURE §1), so the platform builds a
:class:`~sray.model.ray_batch.RayBatch` from a sample here, and nowhere else. No tensor is copied:
the batch shares the sample's tensors (move the sample, or the batch's ``query``, to the device).
"""

from __future__ import annotations

from torch import Tensor

from sray.data_tools.loader.sample_types import SceneQuery, TrainSample
from sray.model.ray_batch import QueryRays, RayBatch


def ray_batch(sample: SceneQuery, pixels: Tensor | None = None) -> RayBatch:
    """The model input of ``sample``: its sources, query camera and bounds, and the rays through ``pixels``.

    pixels: float32 (R, 2) (u, v) of the query image to render; None = a training sample's own
    ``pixels`` (an evaluation sample has none: pass the pixels to render, e.g. a strided grid).
    The sources' depth travels with them (read by the model in ``rgbd`` mode only), and their labels when
    the loader delivered them (the source-view training loss); an evaluation sample's ``query_depth`` never
    enters the batch.
    """
    if pixels is None:
        if not isinstance(sample, TrainSample):
            raise ValueError(f"scene {sample.scene!r}, view {sample.query_id!r}: a {type(sample).__name__} has no "
                             "pixels; pass the (R, 2) pixels to render")
        pixels = sample.pixels
    return RayBatch(src_rgb=sample.sources.rgb, src_K=sample.sources.K, src_c2w=sample.sources.c2w,
                    query=QueryRays(K=sample.query.K, c2w=sample.query.c2w, pixels=pixels,
                                    near=sample.near, far=sample.far), src_depth=sample.sources.depth,
                    src_label=sample.sources.label)
