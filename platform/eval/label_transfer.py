"""Label transfer: per-pixel labels of m posed source views carried into a query view by :func:`transfer_labels`
(docs/fleet.md, "2D label transfer"). Pixel (u, v) is centred at (u, v), cameras are OpenCV's, depth is camera z in
metres (0 = unknown); geometry runs in float64, so rounding never moves with float32 noise.

* ``backward`` (by a depth of the query): each query pixel with depth d > 0 goes to the nearest pixel of every
  source; source j sees it in front of the camera, inside the image, and where |z_j - D_j| < ``tolerance`` * D_j for
  j's own depth D_j > 0 (no test without source depth).
* ``forward`` (by the source depth, the query's camera only): per source a z-buffer keeps each query pixel's nearest
  point (ties: the lowest source pixel index); j sees the pixel when its point is within ``tolerance`` * z* of the
  nearest buffer's z*.
* vote: the most votes win (``ignore_id`` never votes), ties to the label of the best-ranked first voter; no vote:
  :data:`UNSEEN`, scored as a miss (:data:`UNSEEN_RULE`)."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from sray.model.reprojection import project
from sray.model.source_set import rigid_inverse

UNSEEN = -1
"""Transferred label of a query pixel that no source view sees (never a class id)."""

UNSEEN_RULE = ("a pixel without prediction counts as an extra 'unseen' class that is never correct: a miss of "
               "its true class")
"""How every score counts an :data:`UNSEEN` pixel (:func:`unseen_as_class`)."""

MODES = ("backward", "forward")
"""Transfer geometries (module doc)."""


@dataclass(frozen=True)
class LabelTransfer:
    """The labels carried into one query view."""

    labels: Tensor
    """int64 (H, W) class ids; :data:`UNSEEN` where no source view gives a label."""
    seen: Tensor
    """bool (H, W) pixels at least one source view sees, by the transfer's geometry (labelled or not)."""
    rgb: Tensor | None = None
    """float32 (H, W, 3) mean colour of the source pixels seeing each pixel (0: none); None without source colours."""


def project_points(points: Tensor, K: Tensor, c2w: Tensor) -> tuple[Tensor, Tensor]:
    """Pinhole projection of world points (P, 3) into m cameras K (m, 3, 3), c2w (m, 4, 4): float64 uv (m, P, 2)
    and camera depth z (m, P) (uv meaningless where z <= 0)."""
    return project(points.double(), K.double(), rigid_inverse(c2w.double()), min_depth=1e-12)


def unproject(depth: Tensor, K: Tensor, c2w: Tensor) -> Tensor:
    """World points of every pixel of m depth maps (m, H, W) with K (m, 3, 3), c2w (m, 4, 4): float64
    (m, H*W, 3) in row-major pixel order (a pixel with depth 0 lands on its camera centre)."""
    m, h, w = depth.shape
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64, device=depth.device),
                          torch.arange(w, dtype=torch.float64, device=depth.device), indexing="ij")
    pix = torch.stack([u.reshape(-1), v.reshape(-1), torch.ones(h * w, dtype=torch.float64, device=depth.device)], -1)
    rays = pix @ torch.linalg.inv(K.double()).transpose(1, 2)  # (m, P, 3) camera rays with z = 1
    cam = rays * depth.double().reshape(m, -1, 1)  # (m, P, 3)
    c2w64 = c2w.double()
    return cam @ c2w64[:, :3, :3].transpose(1, 2) + c2w64[:, None, :3, 3]  # (m, P, 3)


def nearest_pixel(uv: Tensor, hw: tuple[int, int]) -> tuple[Tensor, Tensor]:
    """Nearest pixel centre of coordinates uv (..., 2): flat index v * W + u (..., ) int64 (0 where outside)
    and whether it lies inside the (H, W) image (..., ) bool."""
    h, w = hw
    iu, iv = torch.floor(uv[..., 0] + 0.5).long(), torch.floor(uv[..., 1] + 0.5).long()
    inside = (iu >= 0) & (iu < w) & (iv >= 0) & (iv < h)
    return torch.where(inside, iv * w + iu, torch.zeros_like(iu)), inside


def point_hits(points: Tensor, source_K: Tensor, source_c2w: Tensor, source_hw: tuple[int, int],
               source_depth: Tensor | None, tolerance: float) -> tuple[Tensor, Tensor, Tensor]:
    """Where world points (P, 3) land in the sources K (m, 3, 3), c2w (m, 4, 4), image ``source_hw``, depth
    (m, H, W) or None (module doc, ``backward``): source pixel index (m, P) int64, visible (m, P) bool and occluded
    (m, P) bool (behind the source's own surface, z >= (1 + ``tolerance``) D; all False without source depth)."""
    uv, z = project_points(points, source_K, source_c2w)  # (m, P, 2), (m, P)
    index, inside = nearest_pixel(uv, source_hw)  # (m, P)
    known = inside & (z > 0)
    if source_depth is None:
        return index, known, torch.zeros_like(known)
    seen_depth = source_depth.double().reshape(source_depth.shape[0], -1).gather(1, index)  # (m, P)
    known = known & (seen_depth > 0)
    visible = known & ((z - seen_depth).abs() < tolerance * seen_depth)
    return index, visible, known & (z >= (1.0 + tolerance) * seen_depth)


def forward_hits(source_depth: Tensor, source_K: Tensor, source_c2w: Tensor, query_K: Tensor,
                 query_c2w: Tensor, hw: tuple[int, int], tolerance: float) -> tuple[Tensor, Tensor]:
    """Which source pixel lands on each query pixel of ``hw`` by splatting with source_depth (m, H, W) (module
    doc, ``forward``). Returns source pixel index (m, Hq*Wq) int64 and visible (m, Hq*Wq) bool."""
    m, h, w = source_depth.shape
    n_query, n_src = hw[0] * hw[1], h * w
    points = unproject(source_depth, source_K, source_c2w).reshape(1, -1, 3)[0]  # (m*P, 3)
    uv, z = project_points(points, query_K[None], query_c2w[None])  # (1, m*P, 2), (1, m*P)
    target, inside = nearest_pixel(uv[0], hw)  # (m*P,)
    valid = inside & (z[0] > 0) & (source_depth.reshape(-1) > 0)
    view = torch.arange(m, device=source_depth.device).repeat_interleave(n_src)  # (m*P,) source of each point
    slot = (view * n_query + target)[valid]  # per-source z-buffer slots
    depth = z[0][valid]
    zbuf = torch.full((m * n_query,), float("inf"), dtype=torch.float64, device=source_depth.device)
    zbuf = zbuf.scatter_reduce(0, slot, depth, "amin")
    front = depth == zbuf[slot]
    pixel = torch.arange(m * n_src, device=source_depth.device)[valid][front] % n_src
    index = torch.full((m * n_query,), n_src, dtype=torch.int64, device=source_depth.device)
    index = index.scatter_reduce(0, slot[front], pixel, "amin").reshape(m, n_query)
    zbuf = zbuf.reshape(m, n_query)
    nearest = zbuf.min(0).values  # (Hq*Wq,) z*, inf where nothing lands
    visible = torch.isfinite(zbuf) & ((zbuf - nearest).abs() < tolerance * nearest)
    return index.clamp_max(n_src - 1), visible


def vote(candidates: Tensor) -> Tensor:
    """Majority label per pixel of per-source candidates (m, P) int64 (:data:`UNSEEN` = no vote): (P,) int64,
    ties to the tied label whose first voter has the lowest source index, :data:`UNSEEN` without votes."""
    m, n = candidates.shape
    voted = candidates >= 0
    if not bool(voted.any()):
        return torch.full((n,), UNSEEN, dtype=torch.int64, device=candidates.device)
    n_labels = int(candidates.max()) + 1
    slot = torch.where(voted, candidates, torch.zeros_like(candidates))  # (m, P)
    counts = torch.zeros(n, n_labels, dtype=torch.int64, device=candidates.device)
    counts.scatter_add_(1, slot.T, voted.T.long())
    order = torch.arange(m, device=candidates.device)[:, None].expand(m, n)
    first = torch.full((n, n_labels), m, dtype=torch.int64, device=candidates.device)
    first.scatter_reduce_(1, slot.T, torch.where(voted, order, torch.full_like(order, m)).T, "amin")
    score = counts * (m + 1) + (m - first)  # more votes first, then the earliest first voter
    return torch.where(voted.any(0), score.argmax(1), torch.full((n,), UNSEEN, device=candidates.device))


def unseen_as_class(pred: Tensor, n_classes: int) -> Tensor:
    """Predictions (any shape) int64 as scored: :data:`UNSEEN` becomes the extra class L = ``n_classes``, which no
    ground truth holds: in an (L+1, L+1) confusion matrix a miss of its true class (:data:`UNSEEN_RULE`)."""
    return torch.where(pred == UNSEEN, torch.full_like(pred, n_classes), pred)


def carried_colours(source_rgb: Tensor, index: Tensor, visible: Tensor, hw: tuple[int, int]) -> Tensor:
    """Mean colour (Hq, Wq, 3) float32 of the source pixels ``index`` (m, Hq*Wq) that are ``visible`` (m, Hq*Wq)
    in source images source_rgb (m, 3, H, W); 0 where no source sees the pixel."""
    m = source_rgb.shape[0]
    colours = source_rgb.float().reshape(m, 3, -1).gather(2, index[:, None].expand(m, 3, -1))  # (m, 3, Hq*Wq)
    weight = visible.float()[:, None]  # (m, 1, Hq*Wq)
    mean = (colours * weight).sum(0) / weight.sum(0).clamp_min(1)  # (3, Hq*Wq)
    return mean.T.reshape(*hw, 3)


def transfer_labels(source_labels: Tensor, source_K: Tensor, source_c2w: Tensor, source_depth: Tensor | None,
                    query_K: Tensor, query_c2w: Tensor, hw: tuple[int, int], mode: str, *,
                    query_depth: Tensor | None = None, tolerance: float = 0.05, ignore_id: int = 255,
                    source_rgb: Tensor | None = None) -> LabelTransfer:
    """Carry source labels (m, H, W) into a query view (module doc): source_K (m, 3, 3); source_c2w (m, 4, 4);
    source_depth (m, H, W) metres, 0 = unknown, or None (``backward`` only); query_K (3, 3); query_c2w (4, 4);
    ``hw`` = the query's (Hq, Wq); ``query_depth`` (Hq, Wq): required by ``backward``, refused by ``forward``;
    ``source_rgb`` (m, 3, H, W) in [0, 1]: carry the colours too (``LabelTransfer.rgb``)."""
    m = source_labels.shape[0]
    depth_shape = source_labels.shape if source_depth is None else source_depth.shape
    if source_labels.shape != depth_shape or source_K.shape != (m, 3, 3) or source_c2w.shape != (m, 4, 4):
        raise ValueError(f"label_transfer: expected source_labels and source_depth (m, H, W), source_K (m, 3, 3), "
                         f"source_c2w (m, 4, 4); got {tuple(source_labels.shape)}, {tuple(depth_shape)}, "
                         f"{tuple(source_K.shape)}, {tuple(source_c2w.shape)}")
    if mode not in MODES:
        raise ValueError(f"label_transfer: mode {mode!r}; use one of {MODES}")
    if mode == "forward" and source_depth is None:
        raise ValueError("label_transfer: forward splatting needs the source depth; without it use the backward "
                         "transfer from a depth of the query")
    if (mode == "backward") != (query_depth is not None):
        raise ValueError(f"label_transfer: mode {mode!r} {'needs' if mode == 'backward' else 'must not read'} the "
                         "query depth; pass query_depth only to the backward (oracle) transfer")
    if source_rgb is not None and tuple(source_rgb.shape) != (m, 3, *source_labels.shape[1:]):
        raise ValueError(f"label_transfer: source_rgb is {tuple(source_rgb.shape)}, expected (m, 3, H, W) = "
                         f"{(m, 3, *source_labels.shape[1:])}")
    if query_depth is not None and tuple(query_depth.shape) != tuple(hw):
        raise ValueError(f"label_transfer: query_depth is {tuple(query_depth.shape)}, the query image {tuple(hw)}")
    if mode == "backward":  # the source pixel each query pixel reaches by its depth: (m, Hq*Wq) each
        points = unproject(query_depth[None], query_K[None], query_c2w[None])[0]  # (Hq*Wq, 3)
        index, visible, _ = point_hits(points, source_K, source_c2w, tuple(source_labels.shape[-2:]), source_depth,
                                       tolerance)
        visible = visible & (query_depth.reshape(1, -1) > 0)
    else:
        index, visible = forward_hits(source_depth, source_K, source_c2w, query_K, query_c2w, tuple(hw), tolerance)
    labels = source_labels.long().reshape(m, -1).gather(1, index)  # (m, Hq*Wq)
    candidates = torch.where(visible & (labels != ignore_id), labels, torch.full_like(labels, UNSEEN))
    rgb = None if source_rgb is None else carried_colours(source_rgb, index, visible, tuple(hw))
    return LabelTransfer(labels=vote(candidates).reshape(hw), seen=visible.any(0).reshape(hw), rgb=rgb)
