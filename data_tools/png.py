"""Lossless PNG codecs of sray's images (8-bit RGB, 16-bit labels, 16-bit depth in millimetres), used by the scene
folder, the shards and the readers alike, so a view survives every hop without loss."""

from __future__ import annotations

import cv2
import numpy as np

DEPTH_SCALE = 1000.0
"""Depth PNG units per metre (millimetres)."""


def encode_png(image: np.ndarray) -> bytes:
    """Lossless PNG bytes of a uint8 (H, W[, 3] RGB) or uint16 (H, W) array."""
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"PNG encoding failed for an array of shape {image.shape} and dtype {image.dtype}")
    return buf.tobytes()


def decode_png(data: bytes, what: str) -> np.ndarray:
    """Decode PNG bytes without loss (16-bit stays 16-bit; colour comes back RGB)."""
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError(f"{what}: not a readable PNG")
    if image.ndim == 3:
        image = cv2.cvtColor(image[..., :3], cv2.COLOR_BGR2RGB)
    return image


def depth_to_png16(depth_m: np.ndarray) -> np.ndarray:
    """float32 metres -> uint16 millimetres (rounded; 0 and non-finite stay 0; clipped at 65.535 m)."""
    d = np.where(np.isfinite(depth_m) & (depth_m > 0), depth_m, 0.0)
    return np.clip(np.rint(d * DEPTH_SCALE), 0, 65535).astype(np.uint16)


def png16_to_depth(depth_mm: np.ndarray) -> np.ndarray:
    """uint16 millimetres -> float32 metres."""
    return depth_mm.astype(np.float32) / DEPTH_SCALE
