"""S-Ray's semantic field read at the ground-truth surface: what density placement costs (an oracle).

For each query pixel with ground-truth depth d > 0, the checkpoint's FINE field is evaluated on its ray and
the argmax of its semantic logits at depth d is the prediction; nothing is composited, so the density never
matters. The field's intra-view attention runs over a ray's samples, so it is given the samples its fine
pass would see if the coarse pass had put all its weight in the bin that holds the surface: ``n_fine``
samples spaced evenly over one coarse bin, (far - near) / n_coarse, centred on d, with d itself the
sample at index n_fine // 2 (with ``fine_samples='union'`` the n_coarse coarse bin centres join them, as
in the union pass). Samples may leave [near, far] when d lies near a bound; they are not clamped.
Pixels without ground-truth depth get no prediction (:data:`~sray.platform.eval.label_transfer.UNSEEN`).
"""

from __future__ import annotations

from collections.abc import Iterator

import torch
from torch import Tensor

from sray.model.ray_chunks import render_chunk_rays
from sray.model.rays import image_pixels, pixel_rays
from sray.model.rendering import sample_uniform
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel, SourceSet
from sray.platform.eval.label_transfer import UNSEEN


def surface_brackets(depth: Tensor, near: Tensor, far: Tensor, n_coarse: int, n_fine: int,
                     union: bool) -> tuple[Tensor, Tensor]:
    """Sorted sample depths z (R, N) around surface depths ``depth`` (R,) (see the module doc) and the index
    (R,) int64 of the sample that is exactly ``depth``. near, far: (R,)."""
    spacing = (far - near) / (n_coarse * n_fine)  # (R,) n_fine samples over one coarse bin
    offsets = torch.arange(n_fine, device=depth.device, dtype=depth.dtype) - n_fine // 2  # (n_fine,)
    z = depth[:, None] + offsets[None, :] * spacing[:, None]  # (R, n_fine)
    if union:
        z = torch.cat([z, sample_uniform(near, far, n_coarse, stratified=False)], dim=-1)
    z, order = z.sort(dim=-1, stable=True)
    return z, (order == n_fine // 2).long().argmax(dim=-1)


@torch.no_grad()
def surface_passes(net: SRayModel, src: SourceSet, K: Tensor, c2w: Tensor, depth: Tensor, pixels: Tensor, near: float,
                   far: float, runtime: Runtime = Runtime()) -> Iterator[tuple[Tensor, dict[str, Tensor], Tensor]]:
    """The fine field run on the rays of ``pixels`` (P,) int64 (flat indices into ``depth`` (H, W), each with a
    known depth) of the query camera K (3, 3), c2w (4, 4), bracketing their ground-truth depths (module doc).

    Yields, per chunk of ``runtime.chunk`` rays (0: by device) run through the field's ``runtime.impl``, the chunk's
    pixel indices (r,), the field's outputs on those rays (``SRayField.forward``: samples along dim 1) and the index
    (r,) of the sample that is the surface."""
    h, w = depth.shape
    device = src.feats.device
    origins, dirs = pixel_rays(K.to(device).float(), c2w.to(device).float(), image_pixels(h, w, device))
    surface = depth.to(device).float().reshape(-1)  # (H*W,)
    chunk = render_chunk_rays(runtime.chunk, device)
    cfg = net.cfg
    pixels = pixels.to(device)
    for start in range(0, pixels.numel(), chunk):
        rays = pixels[start:start + chunk]
        lo = torch.full((rays.numel(),), near, device=device)
        hi = torch.full((rays.numel(),), far, device=device)
        z, at = surface_brackets(surface[rays], lo, hi, cfg.n_coarse, cfg.n_fine, cfg.fine_samples == "union")
        yield rays, net.fine(src, origins[rays], dirs[rays], z, lo, hi, runtime.impl), at


def field_at_surface(net: SRayModel, src: SourceSet, K: Tensor, c2w: Tensor, depth: Tensor, near: float,
                     far: float, runtime: Runtime = Runtime()) -> Tensor:
    """Class ids (H, W) int64 of the fine field at the ground-truth depth (H, W) of the query camera K (3, 3),
    c2w (4, 4) against the encoded sources ``src``; :data:`UNSEEN` where the depth is unknown. Rays run in
    chunks of ``runtime.chunk`` (0: by device) through the field's ``runtime.impl``."""
    h, w = depth.shape
    known = (depth.reshape(-1) > 0).nonzero().squeeze(1)
    pred = torch.full((h * w,), UNSEEN, dtype=torch.int64, device=src.feats.device)
    for rays, out, at in surface_passes(net, src, K, c2w, depth, known, near, far, runtime):
        pred[rays] = out["logits"][torch.arange(rays.numel(), device=rays.device), at].argmax(-1)  # (r, N, L) -> (r,)
    return pred.reshape(h, w).cpu()
