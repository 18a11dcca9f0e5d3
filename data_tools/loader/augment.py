"""Training-sample augmentation that teaches generalization, every option off by default: colour jitter per source view
(exposure, white balance, tone curve, saturation, noise; the fields say how much), so a sample's sources disagree in
photometry while the query's targets stay as they are; random source-view count and neighbour subsets (m sources, m
uniform in [``min_source``, n_source], among the first k ranked neighbours, k uniform in [m, top_k]: near-duplicate or
wide-baseline sets); random source resolution (all sources of a sample resized by one factor in [1 - ``source_scale``,
1]: a Gaussian prefilter against aliasing, then bilinear sampling, which keeps pixel centres exact where OpenCV's area
filter shifts them by up to 0.05 pixel at non-integer factors; intrinsics by the pixel-centre rule). With every option
off nothing is drawn from the sample's generator: samples are bit-identical to no augmentation."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sray.data_tools.perturbations import exposure, gaussian_noise
from sray.data_tools.readers.common import scale_intrinsics


@dataclass(frozen=True)
class Augmentation:
    """Augmentation settings of the training loader (see the module docstring)."""

    colour_ev: float = 0.0
    """Largest exposure change of a source view, in EV stops (uniform in ±colour_ev); 0 = off."""
    channel_ev: float = 0.0
    """Largest extra per-channel change, in EV stops (uniform in ±channel_ev per channel); 0 = off."""
    noise_sigma: float = 0.0
    """Largest Gaussian noise sigma of a source view, in 8-bit levels (uniform in [0, value]); 0 = off."""
    gamma_ev: float = 0.0
    """Largest per-view tone-curve change: channels raised to 2 ** (±gamma_ev) (0.5: exponents 0.71-1.41); 0 = off."""
    saturation_ev: float = 0.0
    """Largest per-view saturation change: distances from the grey level scaled by 2 ** (±saturation_ev); 0 = off."""
    min_source: int = 0
    """Fewest source views of a sample (m uniform in [min_source, n_source]); 0 = always n_source."""
    source_scale: float = 0.0
    """Sources are resized by a factor uniform in [1 - source_scale, 1]; 0 = off."""

    def __post_init__(self) -> None:
        """ValueError naming the field that is out of range."""
        for name in ("colour_ev", "channel_ev", "noise_sigma", "gamma_ev", "saturation_ev", "min_source"):
            if getattr(self, name) < 0:
                raise ValueError(f"augmentation: {name} is {getattr(self, name)}; it must be >= 0 (0 = off)")
        if not 0.0 <= self.source_scale < 1.0:
            raise ValueError(f"augmentation: source_scale is {self.source_scale}; use 0 (off) up to below 1")

    @property
    def jitters_colour(self) -> bool:
        """Whether source images change photometrically."""
        return (self.colour_ev > 0 or self.channel_ev > 0 or self.noise_sigma > 0 or self.gamma_ev > 0
                or self.saturation_ev > 0)

    def source_choice(self, rng: np.random.Generator, n_candidates: int, n_source: int) -> list[int]:
        """Indices into the ranked candidates of a sample's sources (random subset; see module doc)."""
        if self.min_source <= 0:
            return [int(i) for i in rng.choice(n_candidates, n_source, replace=False)]
        m = int(rng.integers(min(self.min_source, n_source), n_source + 1))
        k = int(rng.integers(m, n_candidates + 1))
        return [int(i) for i in rng.choice(k, m, replace=False)]

    def scale(self, rng: np.random.Generator) -> float:
        """The resize factor of one sample's sources (1.0 when off; draws nothing then)."""
        return 1.0 if self.source_scale <= 0 else float(rng.uniform(1.0 - self.source_scale, 1.0))

    def jitter(self, rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """uint8 (H, W, 3) source image with this view's own exposure, channel gains and noise."""
        if not self.jitters_colour:
            return rgb
        ev = float(rng.uniform(-self.colour_ev, self.colour_ev)) if self.colour_ev > 0 else 0.0
        gains = rng.uniform(-self.channel_ev, self.channel_ev, 3) if self.channel_ev > 0 else np.zeros(3)
        out = np.concatenate([exposure(rgb[..., c:c + 1], ev + float(gains[c])) for c in range(3)], axis=2)
        if self.gamma_ev > 0 or self.saturation_ev > 0:
            out = self._tone(out, rng)
        if self.noise_sigma > 0:
            out = gaussian_noise(out, float(rng.uniform(0.0, self.noise_sigma)), rng)
        return out

    def _tone(self, rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """uint8 (H, W, 3) with this view's tone-curve exponent and saturation factor (each 1 when off)."""
        power = 2.0 ** float(rng.uniform(-self.gamma_ev, self.gamma_ev)) if self.gamma_ev > 0 else 1.0
        chroma = 2.0 ** float(rng.uniform(-self.saturation_ev, self.saturation_ev)) if self.saturation_ev > 0 else 1.0
        x = (rgb.astype(np.float64) / 255.0) ** power
        grey = x.mean(axis=2, keepdims=True)
        x = grey + chroma * (x - grey)
        return np.round(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)


def rescale_view(rgb: np.ndarray, K: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(image, float64 K): uint8 (H, W, 3) resized by ``scale`` (Gaussian prefilter, then bilinear; size rounded per
    axis) and K (3, 3) by each axis's exact factor (pixel-centre rule, ``readers.common.scale_intrinsics``)."""
    h, w = rgb.shape[:2]
    nh, nw = max(1, round(h * scale)), max(1, round(w * scale))
    if (nh, nw) == (h, w):
        return rgb, np.asarray(K, np.float64)
    sigma_x, sigma_y = (0.5 * np.sqrt(max(1.0 / f**2 - 1.0, 0.0)) for f in (nw / w, nh / h))  # antialiasing, pixels
    blurred = cv2.GaussianBlur(rgb, (0, 0), sigmaX=max(sigma_x, 1e-3), sigmaY=max(sigma_y, 1e-3))
    return cv2.resize(blurred, (nw, nh), interpolation=cv2.INTER_LINEAR), scale_intrinsics(K, (h, w), (nh, nw))


def rescale_nearest(depth: np.ndarray, size_hw: tuple[int, int]) -> np.ndarray:
    """A per-pixel map (H, W) (float32 depth in metres, or class ids) at ``size_hw`` = (H', W'): each output pixel takes
    the input pixel nearest to its centre, u = (u' + 0.5) W / W' - 0.5 (the geometry of :func:`rescale_view`); values
    are never blended (no depth between a surface and what is behind it, no class between two classes)."""
    h, w = depth.shape
    nh, nw = size_hw
    if (nh, nw) == (h, w):
        return depth
    rows = np.clip(np.rint((np.arange(nh) + 0.5) * h / nh - 0.5), 0, h - 1).astype(np.int64)
    cols = np.clip(np.rint((np.arange(nw) + 0.5) * w / nw - 0.5), 0, w - 1).astype(np.int64)
    return np.ascontiguousarray(depth[rows[:, None], cols[None, :]])
