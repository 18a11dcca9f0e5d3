"""How many rays one forward pass handles, when a setting leaves it to the device (0 = by device).

On a CPU, the per-sample tensors of a chunk (rays x samples x views x channels) are the working set of
every operator; kept near the caches, the same work runs faster. Measured on the 2-core CPU: a render in
chunks of 256 rays took 5.02 s against 6.80 s in chunks of 4800, and a paper-config training step in pieces of
256 rays took 42% less time and 47% less memory than the whole 1024-ray batch at once (8.24 -> 4.81 s,
4.08 -> 2.16 GiB) (docs/performance.md, `runtime.chunk` and `runtime.train_piece`).
A GPU wants the opposite: large chunks keep it busy, so there the render takes 4096 rays per pass and
training computes the batch in one piece.
"""

from __future__ import annotations

import torch

CPU_RAYS = 256
"""Rays per render chunk and per training piece on a CPU."""
CUDA_RENDER_RAYS = 4096
"""Rays per render chunk on a GPU."""


def render_chunk_rays(setting: int, device: torch.device) -> int:
    """Rays per render chunk: ``setting`` when positive, else :data:`CPU_RAYS` on a CPU and
    :data:`CUDA_RENDER_RAYS` elsewhere."""
    if setting < 0:
        raise ValueError(f"sray.model.ray_chunks: a chunk of {setting} rays; use a positive count, or 0 for "
                         "the device's default.")
    return setting or (CPU_RAYS if device.type == "cpu" else CUDA_RENDER_RAYS)


def train_piece_rays(setting: int, device: torch.device, n_rays: int) -> int:
    """Rays per piece of a training step's loss: ``setting`` when positive, else :data:`CPU_RAYS` on a
    CPU and the whole batch of ``n_rays`` elsewhere; never more than ``n_rays``."""
    if setting < 0:
        raise ValueError(f"sray.model.ray_chunks: pieces of {setting} rays; use a positive count, or 0 for "
                         "the device's default.")
    return max(1, min(n_rays, setting or (CPU_RAYS if device.type == "cpu" else n_rays)))
