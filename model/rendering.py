"""Volume rendering along rays: sampling depths, hierarchical resampling and alpha compositing. Samples ``z`` are
ray parameters t of ``o + t d`` (the camera z-depth for ``rays.pixel_rays`` directions); sample k stands for the
interval between the midpoints to its neighbours, closed at near and far (the paper's ``delta_k = z_{k+1} - z_k``
with both ends closed); ``alpha_k = 1 - exp(-sigma_k delta_k |d|)`` with sigma per world unit. Compositing runs in
float32 under autocast (transmittance loses all precision in bfloat16)."""

from __future__ import annotations

import torch
from torch import Tensor

from . import debug_checks

RESERVED_KEYS = ("weights", "opacity", "depth")
"""Keys that ``composite`` writes itself; a rendered value may not use them."""
PDF_EPS = 1e-5
"""Share of the fine-sample mass spread uniformly over [near, far] (see ``sample_pdf``)."""


def _check_bounds(near: Tensor, far: Tensor, n_rays: int, where: str) -> None:
    """ValueError unless ``near`` and ``far`` are (R,) tensors (and, with ``SRAY_DEBUG_CHECKS=1``, near <= far)."""
    for name, t in (("near", near), ("far", far)):
        if not isinstance(t, Tensor) or t.shape != (n_rays,):
            shape = tuple(t.shape) if isinstance(t, Tensor) else type(t).__name__
            raise ValueError(f"sray.model.rendering.{where}: `{name}` must be a tensor of shape ({n_rays},) (one bound "
                             f"per ray), got {shape}; expand a scalar with `torch.full((R,), value)`.")
    if debug_checks.ENABLED and bool((far < near).any()):
        raise ValueError(f"sray.model.rendering.{where}: some rays have far < near; check the scene's depth bounds "
                         "(near must not exceed far).")


def sample_uniform(near: Tensor, far: Tensor, n: int, stratified: bool,
                   generator: torch.Generator | None = None) -> Tensor:
    """Sorted depths (R, n) in [near, far] (R,): ``n`` bin centres, or one uniform draw per bin if ``stratified``."""
    if n < 1:
        raise ValueError(f"sray.model.rendering.sample_uniform: `n` must be >= 1, got {n}.")
    n_rays = near.shape[0] if isinstance(near, Tensor) and near.ndim == 1 else -1
    _check_bounds(near, far, n_rays, "sample_uniform")
    offset: Tensor | float = 0.5
    if stratified:
        offset = torch.rand(n_rays, n, generator=generator, device=near.device, dtype=near.dtype)
    steps = torch.arange(n, device=near.device, dtype=near.dtype)  # (n,)
    return near[:, None] + (far - near)[:, None] * ((steps + offset) / n)  # (R, n)


def bin_edges(z: Tensor, near: Tensor, far: Tensor) -> Tensor:
    """Edges (R, N + 1) of the intervals sorted samples z (R, N) stand for: midpoints inside, near and far outside."""
    mids = 0.5 * (z[:, 1:] + z[:, :-1])  # (R, N-1)
    return torch.cat([near[:, None].to(z.dtype), mids, far[:, None].to(z.dtype)], dim=-1)


def sample_pdf(z: Tensor, weights: Tensor, near: Tensor, far: Tensor, n: int, deterministic: bool,
               generator: torch.Generator | None = None) -> Tensor:
    """Fine depths (R, n), sorted, in [near, far] (R,), without gradient: the inverse CDF of the coarse weights
    (R, N) of sorted samples z (R, N), each spread over its interval plus ``PDF_EPS`` over [near, far], at stratified
    quantiles ``(i + u_i) / n`` (``u_i = 0.5`` when ``deterministic``)."""
    if n < 1:
        raise ValueError(f"sray.model.rendering.sample_pdf: `n` must be >= 1, got {n}.")
    if weights.shape != z.shape or z.ndim != 2:
        raise ValueError("sray.model.rendering.sample_pdf: `z` and `weights` must both be (R, N), got "
                         f"{tuple(z.shape)} and {tuple(weights.shape)}.")
    n_rays = z.shape[0]
    _check_bounds(near, far, n_rays, "sample_pdf")
    z = z.detach().float()
    near, far = near.detach().float(), far.detach().float()
    edges = bin_edges(z, near, far)  # (R, N+1)
    widths = (edges[:, 1:] - edges[:, :-1]).clamp_min(0.0)  # (R, N)
    span = widths.sum(-1, keepdim=True).clamp_min(1e-12)  # (R, 1)
    mass = weights.detach().float().clamp_min(0.0) + PDF_EPS * widths / span  # (R, N)
    cdf = torch.cumsum(mass, dim=-1) / mass.sum(-1, keepdim=True)  # (R, N)
    cdf = torch.cat([torch.zeros_like(cdf[:, :1]), cdf], dim=-1).contiguous()  # (R, N+1)

    steps = torch.arange(n, device=z.device, dtype=torch.float32)  # (n,)
    offset: Tensor | float = 0.5 if deterministic else torch.rand(n_rays, n, generator=generator, device=z.device)
    u = ((steps + offset) / n).expand(n_rays, n).contiguous()  # (R, n) in [0, 1)

    idx = torch.searchsorted(cdf, u, right=True)  # (R, n), in [1, N+1]
    lo = (idx - 1).clamp(0, cdf.shape[-1] - 1)
    hi = idx.clamp(0, cdf.shape[-1] - 1)
    cdf_lo, cdf_hi = cdf.gather(-1, lo), cdf.gather(-1, hi)
    edge_lo, edge_hi = edges.gather(-1, lo), edges.gather(-1, hi)
    denom = cdf_hi - cdf_lo
    frac = torch.where(denom > 0, (u - cdf_lo) / denom.clamp_min(1e-12), torch.zeros_like(u))
    fine = edge_lo + frac.clamp(0.0, 1.0) * (edge_hi - edge_lo)  # (R, n)
    fine = torch.minimum(torch.maximum(fine, near[:, None]), far[:, None])
    return torch.sort(fine, dim=-1).values


def merge_samples(z_coarse: Tensor, z_fine: Tensor) -> Tensor:
    """Sorted union of two sample sets per ray: (R, N1), (R, N2) -> (R, N1 + N2)."""
    if z_coarse.shape[0] != z_fine.shape[0]:
        raise ValueError("sray.model.rendering.merge_samples: both sample sets need the same number of rays, "
                         f"got {z_coarse.shape[0]} and {z_fine.shape[0]}.")
    return torch.sort(torch.cat([z_coarse, z_fine.to(z_coarse.dtype)], dim=-1), dim=-1).values


def composite(sigma: Tensor, z: Tensor, near: Tensor, far: Tensor, values: dict[str, Tensor],
              ray_length: Tensor | None = None) -> dict[str, Tensor]:
    """Alpha-composite sigma (R, N) per world unit and ``values`` name -> (R, N, D) at sorted z (R, N), near, far
    (R,), ray_length (R,) = ``|d|`` (None: unit): ``w_k = T_k alpha_k``, ``T_k = exp(-sum_{j<k} sigma_j delta_j |d|)``.
    Returns ``weights`` (R, N), ``opacity`` (R,) = sum w, ``depth`` (R,) = sum w z (NOT divided by opacity) and each
    value (R, D) = sum_k w_k v_k, in float32."""
    if sigma.ndim != 2 or sigma.shape != z.shape:
        raise ValueError("sray.model.rendering.composite: `sigma` and `z` must both be (R, N), got "
                         f"{tuple(sigma.shape)} and {tuple(z.shape)}.")
    n_rays, n_samples = sigma.shape
    _check_bounds(near, far, n_rays, "composite")
    for key, v in values.items():
        if key in RESERVED_KEYS:
            raise ValueError(f"sray.model.rendering.composite: value name {key!r} is reserved for the compositor's "
                             f"own outputs {RESERVED_KEYS}; rename it.")
        if v.ndim != 3 or v.shape[:2] != (n_rays, n_samples):
            raise ValueError(f"sray.model.rendering.composite: value {key!r} must be (R, N, D) = ({n_rays}, "
                             f"{n_samples}, D), got {tuple(v.shape)}.")
    with torch.autocast(device_type=sigma.device.type, enabled=False):
        z32 = z.float()
        edges = bin_edges(z32, near.float(), far.float())  # (R, N+1)
        delta = (edges[:, 1:] - edges[:, :-1]).clamp_min(0.0)  # (R, N) in ray parameter
        if ray_length is not None:
            if ray_length.shape != (n_rays,):
                raise ValueError(f"sray.model.rendering.composite: `ray_length` must be ({n_rays},), got "
                                 f"{tuple(ray_length.shape)}.")
            delta = delta * ray_length.float()[:, None]  # (R, N) metric interval lengths
        tau = sigma.float() * delta  # (R, N) optical depth of each interval
        alpha = -torch.expm1(-tau)  # 1 - exp(-tau), accurate for small tau
        # (R, N) exclusive sum sum_{j<k} tau_j; shifting (not subtracting tau) keeps it exact
        before = torch.cat([torch.zeros_like(tau[:, :1]), torch.cumsum(tau[:, :-1], -1)], -1)
        weights = torch.exp(-before) * alpha  # (R, N)
        out = {"weights": weights, "opacity": weights.sum(-1), "depth": (weights * z32).sum(-1)}
        for key, v in values.items():
            out[key] = torch.einsum("rn,rnd->rd", weights, v.float())
    return out
