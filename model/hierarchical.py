"""The one hierarchical renderer of ``sray.model``, coarse pass -> inverse-CDF resampling -> fine pass over a batch of
rays, for any method's :data:`PassField` (whole views: ``view_render``). Density is per world unit and ``composite``
scales the z spacing by ``|d|``, so non-unit ``pixel_rays`` directions render the same surface at every pixel."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from .rendering import composite, merge_samples, sample_pdf, sample_uniform

PASSES = ("coarse", "fine")
"""Render passes in order."""
IMAGE_KEYS = ("logits", "rgb", "depth", "opacity")
"""Per-pass outputs ``view_render.render_view`` assembles into images (weights and z are left out)."""

PassField = Callable[[str, Tensor, Tensor, Tensor, Tensor, Tensor], dict[str, Tensor]]
"""A method's per-sample network: ``field(pass_name, origins (R, 3), dirs (R, 3), z (R, N), near (R,), far (R,))
-> {"sigma": (R, N) >= 0 per world unit, "logits": (R, N, L), "rgb": (R, N, 3)}``."""

CoarseSampler = Callable[[Tensor, Tensor, Tensor, Tensor, int, bool, torch.Generator | None], Tensor]
"""``sampler(origins (R, 3), dirs (R, 3), near (R,), far (R,), n, stratified, generator) -> z (R, n)``
sorted coarse depths in [near, far] (the RGB-D mode's ``depth_sampling``); None = ``sample_uniform``."""


def per_ray_bounds(value: Tensor | float, n_rays: int, like: Tensor, name: str) -> Tensor:
    """A bound given as a Python scalar, a 0-d or an (R,) tensor, as a float32 (R,) tensor on ``like``'s device."""
    t = torch.as_tensor(value, dtype=torch.float32, device=like.device)
    if t.ndim == 0:
        return t.expand(n_rays)
    if t.shape != (n_rays,):
        raise ValueError(f"sray.model.hierarchical: `{name}` must be a scalar or ({n_rays},), got {tuple(t.shape)}.")
    return t


def _render_pass(field: PassField, name: str, origins: Tensor, dirs: Tensor, z: Tensor, near: Tensor,
                 far: Tensor, ray_length: Tensor) -> dict[str, Tensor]:
    """One pass: the field at depths z (R, N), composited. Returns the CONTRACTS.md pass dict."""
    out = field(name, origins, dirs, z, near, far)
    comp = composite(out["sigma"], z, near, far, {"logits": out["logits"], "rgb": out["rgb"]}, ray_length)
    return {"logits": comp["logits"], "rgb": comp["rgb"], "depth": comp["depth"], "opacity": comp["opacity"],
            "weights": comp["weights"], "z": z}


def coarse_depths(sampler: CoarseSampler | None, origins: Tensor, dirs: Tensor, near: Tensor, far: Tensor,
                  n: int, stratified: bool, generator: torch.Generator | None = None) -> Tensor:
    """Sorted coarse depths (R, n): ``sampler``'s, or ``sample_uniform``'s equal bins when it is None."""
    if sampler is None:
        return sample_uniform(near, far, n, stratified, generator)
    return sampler(origins, dirs, near, far, n, stratified, generator)


def render_rays(field: PassField, origins: Tensor, dirs: Tensor, near: Tensor | float, far: Tensor | float,
                n_coarse: int, n_fine: int, stratified: bool, generator: torch.Generator | None = None,
                fine_samples: str = "union",
                coarse_sampler: CoarseSampler | None = None) -> dict[str, dict[str, Tensor]]:
    """Render rays o + t d, t in [near, far], coarse then fine: origins, dirs (R, 3), near, far scalars or (R,);
    ``stratified`` jitters the samples (training); the fine pass evaluates the ``"union"`` of coarse and resampled
    depths or the ``"new"`` ones only; ``coarse_sampler`` None: equal bins. Returns ``{"coarse": pass, "fine":
    pass}``, each with ``logits`` (R, L), ``rgb`` (R, 3), ``depth``, ``opacity`` (R,), ``weights``, ``z`` (R, N)."""
    if origins.ndim != 2 or origins.shape[-1] != 3 or dirs.shape != origins.shape:
        raise ValueError(f"sray.model.hierarchical.render_rays: origins and dirs must both be (R, 3), got "
                         f"{tuple(origins.shape)} and {tuple(dirs.shape)}.")
    n_rays = origins.shape[0]
    origins, dirs = origins.float(), dirs.float()
    near_r = per_ray_bounds(near, n_rays, origins, "near")
    far_r = per_ray_bounds(far, n_rays, origins, "far")
    ray_length = dirs.norm(dim=-1)  # (R,) world length of one unit of t
    z_coarse = coarse_depths(coarse_sampler, origins, dirs, near_r, far_r, n_coarse, stratified, generator)  # (R, Nc)
    coarse = _render_pass(field, "coarse", origins, dirs, z_coarse, near_r, far_r, ray_length)
    z_fine = sample_pdf(z_coarse, coarse["weights"].detach(), near_r, far_r, n_fine,
                        deterministic=not stratified, generator=generator)  # (R, Nf)
    if fine_samples not in ("union", "new"):
        raise ValueError(f"sray.model.hierarchical.render_rays: fine_samples is {fine_samples!r}; "
                         "use 'union' or 'new'.")
    z_all = merge_samples(z_coarse, z_fine) if fine_samples == "union" else z_fine  # (R, Nc + Nf) or (R, Nf)
    fine = _render_pass(field, "fine", origins, dirs, z_all, near_r, far_r, ray_length)
    return {"coarse": coarse, "fine": fine}
