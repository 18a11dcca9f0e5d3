"""NeRF's frequency (positional) encoding of coordinates."""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn


class PositionalEncoding(nn.Module):
    """gamma(x) = (x, sin(2^0 pi x), cos(2^0 pi x), ..., sin(2^(L-1) pi x), cos(2^(L-1) pi x)): (..., in_dim) ->
    (..., in_dim * (1 + 2 L)), per frequency the sines of all coordinates, then their cosines. Inputs in about
    [-1, 1], so the lowest band (NeRF's factor pi) spans the scene once."""

    freq_bands: Tensor

    def __init__(self, in_dim: int, n_freqs: int) -> None:
        super().__init__()
        if in_dim < 1 or n_freqs < 0:
            raise ValueError("sray.model.positional_encoding.PositionalEncoding: need in_dim >= 1 and n_freqs >= 0, "
                             f"got in_dim={in_dim}, n_freqs={n_freqs}.")
        self.in_dim = in_dim
        self.n_freqs = n_freqs
        self.out_dim = in_dim * (1 + 2 * n_freqs)
        bands = math.pi * (2.0 ** torch.arange(n_freqs, dtype=torch.float32))  # (L,)
        self.register_buffer("freq_bands", bands, persistent=False)

    def forward(self, x: Tensor) -> Tensor:
        """Encode x: (..., in_dim) -> (..., out_dim)."""
        if x.shape[-1] != self.in_dim:
            raise ValueError(f"sray.model.positional_encoding.PositionalEncoding: last dimension must be "
                             f"{self.in_dim}, got input of shape {tuple(x.shape)}.")
        if self.n_freqs == 0:
            return x
        scaled = x[..., None, :] * self.freq_bands.to(x.dtype)[:, None]  # (..., L, in_dim)
        per_band = torch.cat([torch.sin(scaled), torch.cos(scaled)], dim=-1)  # (..., L, 2 in_dim)
        return torch.cat([x, per_band.flatten(-2)], dim=-1)  # (..., in_dim (1 + 2L))
