"""Rays per forward pass when a setting leaves it to the device (0): on a CPU small chunks keep a chunk's tensors near
the caches (measured in docs/performance.md, ``runtime.chunk``, ``runtime.train_piece``); a GPU wants large ones."""

from __future__ import annotations

import torch

CPU_RAYS = 256
"""Rays per render chunk and per training piece on a CPU."""
CUDA_RENDER_RAYS = 4096
"""Rays per render chunk on a GPU."""


def render_chunk_rays(setting: int, device: torch.device) -> int:
    """Rays per render chunk: ``setting`` when positive, else 256 on a CPU and 4096 elsewhere."""
    if setting < 0:
        raise ValueError(f"sray.model.ray_chunks: a chunk of {setting} rays; use a positive count, or 0 for the "
                         "device's default.")
    return setting or (CPU_RAYS if device.type == "cpu" else CUDA_RENDER_RAYS)


def train_piece_rays(setting: int, device: torch.device, n_rays: int) -> int:
    """Rays per training piece: ``setting`` if positive, else 256 on a CPU, the batch elsewhere; <= ``n_rays``."""
    if setting < 0:
        raise ValueError(f"sray.model.ray_chunks: pieces of {setting} rays; use a positive count, or 0 for the "
                         "device's default.")
    return max(1, min(n_rays, setting or (CPU_RAYS if device.type == "cpu" else n_rays)))
