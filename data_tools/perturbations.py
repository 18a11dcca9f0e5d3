"""Seeded perturbations of posed views (units in each docstring), swept by ``sray stability``, usable as augmentation;
pure functions drawing only from the given generator: a (seed, level) pair always gives one perturbation."""

from __future__ import annotations

import cv2
import numpy as np


def random_unit_vector(rng: np.random.Generator) -> np.ndarray:
    """A direction drawn uniformly on the unit sphere, (3,) float64."""
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def noisy_pose(c2w: np.ndarray, rotation_deg: float, translation_cm: float, rng: np.random.Generator) -> np.ndarray:
    """``c2w`` (4, 4, metres) turned by exactly ``rotation_deg`` degrees about a random axis through the camera
    centre and moved by exactly ``translation_cm`` centimetres in a random direction; a new (4, 4) float64 matrix."""
    if rotation_deg < 0 or translation_cm < 0:
        raise ValueError(f"pose noise magnitudes must be >= 0, got {rotation_deg} deg and {translation_cm} cm")
    out = np.array(c2w, dtype=np.float64, copy=True)
    turn, _ = cv2.Rodrigues(random_unit_vector(rng).reshape(3, 1) * np.deg2rad(rotation_deg))
    out[:3, :3] = turn @ out[:3, :3]
    out[:3, 3] = out[:3, 3] + random_unit_vector(rng) * translation_cm / 100.0
    return out


def _to_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def gaussian_noise(rgb: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """uint8 (H, W, 3) plus N(0, sigma²) per channel (sigma in 8-bit levels), clipped; uint8 out."""
    if sigma < 0:
        raise ValueError(f"noise sigma must be >= 0 (8-bit levels), got {sigma}")
    return _to_uint8(rgb.astype(np.float64) + rng.normal(0.0, sigma, rgb.shape)) if sigma > 0 else rgb.copy()


def motion_blur_kernel(length_px: int, angle_rad: float) -> np.ndarray:
    """A straight blur kernel (length_px, length_px) float64 along ``angle_rad``, summing to 1."""
    if length_px < 1 or length_px % 2 == 0:
        raise ValueError(f"motion blur length must be an odd number of pixels >= 1, got {length_px}")
    kernel = np.zeros((length_px, length_px), np.float64)
    c = (length_px - 1) / 2
    for t in np.linspace(-c, c, 4 * length_px):
        kernel[int(round(c + t * np.sin(angle_rad))), int(round(c + t * np.cos(angle_rad)))] = 1.0
    return kernel / kernel.sum()


def motion_blur(rgb: np.ndarray, length_px: int, rng: np.random.Generator) -> np.ndarray:
    """uint8 (H, W, 3) blurred along a random direction by a ``length_px`` kernel (reflected borders keep the mean)."""
    if length_px == 1:
        return rgb.copy()
    kernel = motion_blur_kernel(length_px, float(rng.uniform(0.0, np.pi)))
    return _to_uint8(cv2.filter2D(rgb.astype(np.float64), -1, kernel, borderType=cv2.BORDER_REFLECT))


def exposure(rgb: np.ndarray, ev: float) -> np.ndarray:
    """uint8 (H, W, 3) with intensities multiplied by 2**ev (clipped): ev > 0 brighter, < 0 darker."""
    return _to_uint8(rgb.astype(np.float64) * 2.0 ** ev)


def jpeg(rgb: np.ndarray, quality: int) -> np.ndarray:
    """uint8 (H, W, 3) RGB after a JPEG round trip at ``quality`` (1-100; OpenCV's encoder, 4:2:0 chroma)."""
    if not 1 <= quality <= 100:
        raise ValueError(f"JPEG quality must be in 1..100, got {quality}")
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV could not encode the image as JPEG")
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def occlusion_mask(hw: tuple[int, int], fraction: float, rng: np.random.Generator) -> np.ndarray:
    """bool (H, W) with exactly ``round(fraction · H · W)`` True pixels: random rectangles (sides 5-35 % of the
    image's) until the target is reached, the last one's excess pixels left out in raster order (a partial row)."""
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"occlusion fraction must be in [0, 1], got {fraction}")
    h, w = hw
    target = int(round(fraction * h * w))
    mask = np.zeros((h, w), bool)
    while int(mask.sum()) < target:
        rh = int(rng.integers(max(1, h // 20), max(2, h * 7 // 20) + 1))
        rw = int(rng.integers(max(1, w // 20), max(2, w * 7 // 20) + 1))
        y, x = int(rng.integers(0, h - rh + 1)), int(rng.integers(0, w - rw + 1))
        new = np.zeros_like(mask)
        new[y:y + rh, x:x + rw] = True
        new &= ~mask
        excess = int(mask.sum() + new.sum()) - target
        if excess > 0:
            ys, xs = np.nonzero(new)
            new[ys[len(ys) - excess:], xs[len(xs) - excess:]] = False
        mask |= new
    return mask


def occlude(rgb: np.ndarray, fraction: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """uint8 (H, W, 3) with ``fraction`` of its pixels covered by flat random colours; returns (image, mask)."""
    mask = occlusion_mask(rgb.shape[:2], fraction, rng)
    out = rgb.copy()
    n, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    for k in range(1, n):
        out[labels == k] = rng.integers(0, 256, 3, dtype=np.uint8)
    return out, mask
