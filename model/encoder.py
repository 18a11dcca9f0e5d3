"""The ResUNet image encoder of the appendix table "Semantic feature extraction" (L1-L19), channels scaled with the
first layer's (``SRayConfig.encoder_width``, 16 = the table): four stride-2 stages to 1/16 (L1, L2, L3, L5), two
up-sampling stages back to 1/4 with the L4 and L2 skips; ReLU after each decoder conv but L19 (a linear decoder would
fold L14 into L15); up-sampling to the skip's exact size (sizes not divisible by 16). Padding k // 2 centres stride-2
output pixel j on input pixel 2j, so feature pixel j sits on image pixel 4j (``reprojection``, ``upsample_to``)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

FEATURE_STRIDE = 4
"""Feature pixel (j, i) is centred on full-resolution pixel (FEATURE_STRIDE * j, FEATURE_STRIDE * i)."""

MIN_IMAGE_SIZE = 32
"""Smallest image side the encoder accepts (instance norm needs > 1 pixel at 1/16 resolution)."""

def _norm(channels: int) -> nn.Module:
    """Instance normalisation with a learned affine map and per-image statistics only."""
    return nn.InstanceNorm2d(channels, affine=True, track_running_stats=False)


def upsample_to(x: Tensor, size: tuple[int, int]) -> Tensor:
    """Centre-aligned bilinear 2x up-sampling (B, C, h, w) -> (B, C, *size <= (2h, 2w)): pixel j reads j / 2."""
    h, w = x.shape[-2:]
    if size[0] > 2 * h or size[1] > 2 * w:
        raise ValueError(f"sray.model.encoder.upsample_to: target {size} exceeds twice {(h, w)}.")
    # align_corners=True to (2h-1, 2w-1) puts output j exactly at input j/2
    up = F.interpolate(x, size=(2 * h - 1, 2 * w - 1), mode="bilinear", align_corners=True)
    up = F.pad(up, (0, 1, 0, 1), mode="replicate")  # (B, C, 2h, 2w), last row/col clamped
    return up[..., : size[0], : size[1]]


class ResBlock(nn.Module):
    """Two 3x3 convs with instance normalisation and ReLU plus a (projected when needed) shortcut."""

    def __init__(self, c_in: int, c_out: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False)
        self.norm1 = _norm(c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False)
        self.norm2 = _norm(c_out)
        self.shortcut: nn.Module = nn.Identity()
        if stride != 1 or c_in != c_out:
            self.shortcut = nn.Sequential(nn.Conv2d(c_in, c_out, 1, stride, bias=False), _norm(c_out))

    def forward(self, x: Tensor) -> Tensor:
        """(B, c_in, H, W) -> (B, c_out, ceil(H / stride), ceil(W / stride))."""
        y = F.relu(self.norm1(self.conv1(x)))
        y = self.norm2(self.conv2(y))
        return F.relu(y + self.shortcut(x))


def _conv_norm(c_in: int, c_out: int, k: int, relu: bool) -> nn.Sequential:
    """Conv k x k (stride 1, same padding) + instance normalisation (+ ReLU)."""
    return nn.Sequential(nn.Conv2d(c_in, c_out, k, 1, k // 2, bias=False), _norm(c_out), *([nn.ReLU()] if relu else []))


class ResUNetEncoder(nn.Module):
    """Shared per-view encoder: RGB (B, 3, H, W) in [0, 1] -> features (B, C, ceil(H/4), ceil(W/4))."""

    def __init__(self, out_dim: int = 32, width: int = 16) -> None:
        """``out_dim`` feature channels (L19); ``width`` channels of L1, every other layer scaled with it."""
        super().__init__()
        if width < 1:
            raise ValueError(f"sray.model.encoder: width is {width}; give the first layer at least one channel")
        w1, w2, w4, w8 = width, 2 * width, 4 * width, 8 * width
        self.stem = nn.Sequential(nn.Conv2d(3, w1, 7, 2, 3, bias=False), _norm(w1), nn.ReLU())  # L1
        self.down2 = ResBlock(w1, w2, 2)  # L2
        self.down3 = nn.Sequential(ResBlock(w2, w4, 2), ResBlock(w4, w4, 1))  # L3, L4
        self.down4 = nn.Sequential(ResBlock(w4, w8, 2), *[ResBlock(w8, w8, 1) for _ in range(5)])  # L5-L10
        self.reduce4 = _conv_norm(w8, w4, 3, True)  # L11
        self.merge3 = nn.Sequential(_conv_norm(2 * w4, w4, 3, True), _conv_norm(w4, w2, 3, True))  # L14, L15
        self.merge2 = _conv_norm(2 * w2, w2, 3, True)  # L18
        self.head = _conv_norm(w2, out_dim, 1, False)  # L19

    def forward(self, rgb: Tensor) -> Tensor:
        """rgb: (B, 3, H, W) in [0, 1]; returns (B, C, ceil(ceil(H/2)/2), ceil(ceil(W/2)/2))."""
        if rgb.ndim != 4 or rgb.shape[1] != 3:
            raise ValueError(f"sray.model.encoder: expected source images (m, 3, H, W), got {tuple(rgb.shape)}.")
        if min(rgb.shape[-2:]) < MIN_IMAGE_SIZE:
            raise ValueError(f"sray.model.encoder: source images are {tuple(rgb.shape[-2:])}; both sides "
                             f"must be at least {MIN_IMAGE_SIZE} pixels (resize the scene up).")
        x1 = self.stem(rgb * 2.0 - 1.0)  # (B, w, H/2, W/2)
        x2 = self.down2(x1)  # (B, 2w, H/4, W/4)
        x3 = self.down3(x2)  # (B, 4w, H/8, W/8)
        x4 = self.reduce4(self.down4(x3))  # (B, 4w, H/16, W/16)
        y3 = self.merge3(torch.cat([upsample_to(x4, x3.shape[-2:]), x3], 1))  # (B, 2w, H/8, W/8)
        y2 = self.merge2(torch.cat([upsample_to(y3, x2.shape[-2:]), x2], 1))  # (B, 2w, H/4, W/4)
        return self.head(y2)  # (B, C, H/4, W/4)
