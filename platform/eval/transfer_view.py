"""The ``2d-transfer`` prediction of one query view: a 2D segmenter labels the source images, whose labels and
colours are splatted into the query by the SOURCE depth (``label_transfer``, ``forward``), reading of the query only
its camera (docs/fleet.md, "2D label transfer"). Ceilings row c is this transfer; the method is scored through
:func:`transfer_renderer` (a pixel no source labels: all logits -inf, ``UNSEEN``).
"""

from __future__ import annotations

import torch
from torch import Tensor

from sray.data_tools.loader.sample_types import EvalSample, QueryCamera, SourceViews
from sray.model.view_render import RayRenderer
from sray.platform.eval.label_transfer import UNSEEN, LabelTransfer, nearest_pixel, project_points, transfer_labels
from sray.platform.eval.segmenter import Segmenter


def source_depth_transfer(labels: Tensor, sources: SourceViews, query: QueryCamera, tolerance: float,
                          ignore_id: int, source_rgb: Tensor | None = None) -> LabelTransfer:
    """Per-source labels (m, H, W) int64 splatted into the query camera's (H, W) image by the sources' depth;
    ``source_rgb`` (m, 3, H, W): carry those colours too. ValueError when the sources carry no depth."""
    if sources.depth is None:
        raise ValueError("2d-transfer: the source views carry no depth; it carries labels by the source depth, "
                         "so evaluate shards written with depth (every sray shard holds it)")
    return transfer_labels(labels, sources.K, sources.c2w, sources.depth, query.K, query.c2w,
                           tuple(sources.depth.shape[-2:]), "forward", tolerance=tolerance, ignore_id=ignore_id,
                           source_rgb=source_rgb)


@torch.no_grad()
def segment_and_transfer(segmenter: Segmenter, sources: SourceViews, query: QueryCamera,
                         tolerance: float) -> LabelTransfer:
    """The segmenter's labels of the source images (m, 3, H, W), with their colours, carried into the query view
    (:func:`source_depth_transfer`) on the segmenter's and the views' device."""
    labels = segmenter.predict(sources.rgb)  # (m, H, W)
    return source_depth_transfer(labels, sources, query, tolerance, segmenter.cfg.ignore_id, source_rgb=sources.rgb)


def pixel_lookup_renderer(transfer: LabelTransfer, query: QueryCamera, n_classes: int) -> RayRenderer:
    """A ray renderer over the transferred maps (with colours) of the query camera: each ray (origins, dirs (R, 3))
    reads the nearest pixel; ``logits`` (R, L) 0 at its label and -inf elsewhere (all -inf without a label or
    off the image), ``rgb`` (R, 3) the carried colour (0 there). Both passes are the same maps; near/far unused."""
    if transfer.rgb is None:
        raise ValueError("2d-transfer: pass the source colours to the transfer; its renderer returns them")
    hw = (int(transfer.labels.shape[0]), int(transfer.labels.shape[1]))
    labels, colours = transfer.labels.reshape(-1), transfer.rgb.reshape(-1, 3)  # (Hq*Wq,), (Hq*Wq, 3)

    def render(origins: Tensor, dirs: Tensor, near: Tensor, far: Tensor) -> dict[str, dict[str, Tensor]]:
        uv, z = project_points(origins + dirs, query.K[None], query.c2w[None])  # (1, R, 2), (1, R)
        index, inside = nearest_pixel(uv[0], hw)  # (R,)
        hit = inside & (z[0] > 0)  # (R,) the ray meets a pixel of the image
        label = torch.where(hit, labels[index], torch.full_like(index, UNSEEN))  # (R,)
        known = label != UNSEEN
        logits = torch.full((len(label), n_classes), float("-inf"), device=label.device)  # (R, L)
        logits[known, label[known]] = 0.0
        rgb = torch.where(hit[:, None], colours[index], torch.zeros_like(colours[index]))  # (R, 3)
        out = {"logits": logits, "rgb": rgb}  # (R, L), (R, 3)
        return {"coarse": out, "fine": out}

    return render


def transfer_renderer(segmenter: Segmenter, sample: EvalSample, tolerance: float,
                      device: torch.device) -> RayRenderer:
    """The ``2d-transfer`` ray renderer of one evaluation sample: its sources and query camera moved to ``device``
    (the segmenter's), segmented and splatted once, then read per ray (:func:`pixel_lookup_renderer`)."""
    sources, query = sample.sources.to(device), sample.query.to(device)
    return pixel_lookup_renderer(segment_and_transfer(segmenter, sources, query, tolerance), query,
                                 segmenter.cfg.n_classes)
