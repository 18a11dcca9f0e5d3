"""Structural similarity (SSIM) of Wang, Bovik, Sheikh and Simoncelli (IEEE TIP 2004): an 11x11 Gaussian window
(sigma 1.5, sum 1) where it lies fully inside the image (no padding), weighted (population) variances,
C1 = (0.01 L)^2, C2 = (0.03 L)^2; colour scored per channel; the mean over positions, channels and images."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_K1 = 0.01
SSIM_K2 = 0.03
SSIM_PROTOCOL = (f"Wang et al. 2004: {SSIM_WINDOW}x{SSIM_WINDOW} Gaussian window, sigma {SSIM_SIGMA}, "
                 f"K1 {SSIM_K1}, K2 {SSIM_K2}, data range 1, valid positions only, mean over channels")


def gaussian_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> Tensor:
    """Normalised 2-D Gaussian weights (size, size), float64, centred on the middle pixel."""
    coords = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
    g = torch.exp(-(coords**2) / (2 * sigma**2))
    g = g / g.sum()
    return g[:, None] * g[None, :]


def _as_batch_channels_first(x: Tensor) -> Tensor:
    """(H, W) | (H, W, C) | (B, H, W, C) -> (B, C, H, W) float64."""
    if x.ndim not in (2, 3, 4):
        raise ValueError(f"sray.model.ssim.ssim: images must be (H, W), (H, W, C) or (B, H, W, C), got shape "
                         f"{tuple(x.shape)}.")
    if x.ndim == 2:
        x = x[None, :, :, None]
    elif x.ndim == 3:
        x = x[None]
    return x.permute(0, 3, 1, 2).to(torch.float64)


def ssim(pred: Tensor, target: Tensor) -> float:
    """Mean SSIM of two images (or batches) (H, W), (H, W, C) or (B, H, W, C), H, W >= 11, values in [0, 1]."""
    if pred.shape != target.shape:
        raise ValueError(f"sray.model.ssim.ssim: shapes differ: {tuple(pred.shape)} vs {tuple(target.shape)}.")
    x, y = _as_batch_channels_first(pred), _as_batch_channels_first(target)
    _, channels, height, width = x.shape
    if height < SSIM_WINDOW or width < SSIM_WINDOW:
        raise ValueError(f"sray.model.ssim.ssim: images must be at least {SSIM_WINDOW}x{SSIM_WINDOW} pixels, "
                         f"got {height}x{width}.")
    kernel = gaussian_window().to(x.device).expand(channels, 1, SSIM_WINDOW, SSIM_WINDOW)  # depthwise (C, 1, k, k)

    def local_mean(t: Tensor) -> Tensor:
        return F.conv2d(t, kernel, groups=channels)  # (B, C, H-k+1, W-k+1)

    mu_x, mu_y = local_mean(x), local_mean(y)
    var_x = local_mean(x * x) - mu_x**2
    var_y = local_mean(y * y) - mu_y**2
    cov = local_mean(x * y) - mu_x * mu_y
    c1, c2 = SSIM_K1**2, SSIM_K2**2  # data range 1
    num = (2 * mu_x * mu_y + c1) * (2 * cov + c2)
    den = (mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2)
    return float((num / den).mean())
