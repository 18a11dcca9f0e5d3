"""Held-out regions of the generator's appearance and geometry spaces and which one a scene is drawn from: a world's
test rooms come from one of :data:`SPLITS` (docs/data.md, "Shifted test splits"); training rooms never enter a held-out
region (``tests/test_synth_shift.py``). :func:`current` says the region being drawn from; :func:`drawing` sets it for
one scene (a context variable: per thread and process)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import numpy as np

SPLITS = ("in-distribution", "validation", "appearance-shift", "geometry-shift")
"""Test-room splits of a world; ``validation`` is the training distribution from a seed stream of its own."""

# Held-out appearance (training values in brackets).
HELD_OUT_HUE = (0.50, 0.75)  # HSV hue band of held-out surface colours: cyan-blue to violet
HELD_OUT_SAT = 0.25  # saturation from which a colour in that band is held out
SHIFT_COLOUR_PROB = 0.5  # share of a shifted room's surface colours moved into the held-out region
HELD_OUT_KELVIN = (1500.0, 2100.0)  # ceiling-lamp colour temperatures (training: 2400 K and above)
LOW_LIGHT_TOP = 0.9  # highest main light, metres above the floor (training: the ceiling lamp)
TRAIN_EXPOSURE_EV = 0.6  # training exposure: 2 ** uniform(-0.6, 0.6)
HELD_OUT_EXPOSURE_EV = (0.9, 1.4)  # shifted exposure: 2 ** (±uniform(0.9, 1.4))
TRAIN_TONE = (1.6, 2.2)  # training (k, gamma) of the tone curve rgb = (1 - exp(-k x)) ** (1 / gamma)
HELD_OUT_TONE_K = (2.4, 3.2)
HELD_OUT_GAMMA = (1.5, 1.9)
HELD_OUT_NOISE = (3.0, 8.0)  # sensor noise sigma, 8-bit levels (training: 0)
# Held-out geometry.
TRAIN_SCALE = (0.9, 1.2)  # training room scale factor applied to a room type's floor ranges
HELD_OUT_SCALE = (1.3, 1.55)
HELD_OUT_CEILING = (3.1, 3.6)  # ceiling heights, metres (training: 3.0 at most)
HELD_OUT_WALL_GAP = (0.3, 0.6)  # gap between a wall and the furniture against it (training: 0.015 m)
HELD_OUT_CAMERA = (0.55, 0.95)  # camera heights, metres (training: ``trajectory.HEIGHT_RANGE``)
HELD_OUT_LOOK = (1.0, 1.9)  # look-at target heights: level or up (training 0.2-1.3, looking down)


@dataclass(frozen=True)
class Domain:
    """Which region a scene's appearance and its geometry are drawn from."""

    appearance_shift: bool = False
    geometry_shift: bool = False
    randomise: float = 0.0
    """Strength (0-1) of the training rooms' appearance randomisation (never leaving the training region); 0 = off."""


_CURRENT: ContextVar[Domain] = ContextVar("sray_synth_domain", default=Domain())


def domain_of(split: str, randomise: float = 0.0) -> Domain:
    """A split's region with randomisation ``randomise`` (0-1, training rooms only); ValueError names valid values."""
    if split not in SPLITS:
        raise ValueError(f"split {split!r} is not one of {SPLITS}")
    if not 0.0 <= randomise <= 1.0:
        raise ValueError(f"randomise {randomise} must lie in [0, 1] (0 = off)")
    if randomise > 0 and split != "in-distribution":
        raise ValueError(f"appearance randomisation is for training rooms; split {split!r} must be drawn without it")
    return Domain(appearance_shift=split == "appearance-shift", geometry_shift=split == "geometry-shift",
                  randomise=randomise)


def current() -> Domain:
    """The region the scene being generated is drawn from (the training one outside :func:`drawing`)."""
    return _CURRENT.get()


@contextmanager
def drawing(domain: Domain) -> Iterator[Domain]:
    """Generate inside ``domain`` for the duration of the block."""
    token = _CURRENT.set(domain)
    try:
        yield domain
    finally:
        _CURRENT.reset(token)


def held_out_colour(hue: float, sat: float) -> bool:
    """Whether an HSV colour lies in the held-out colour region."""
    return HELD_OUT_HUE[0] <= hue % 1.0 < HELD_OUT_HUE[1] and sat >= HELD_OUT_SAT


def surface_colour(rng: np.random.Generator, hue: float, sat: float) -> tuple[float, float]:
    """(hue, saturation) of a surface colour as the region allows: in training a held-out colour is desaturated below
    :data:`HELD_OUT_SAT` (no draw); when shifted a share :data:`SHIFT_COLOUR_PROB` moves into it."""
    if current().appearance_shift:
        if rng.random() < SHIFT_COLOUR_PROB:
            return float(rng.uniform(*HELD_OUT_HUE)), float(rng.uniform(0.3, 0.85))
        return hue, sat
    return (hue, sat * (HELD_OUT_SAT - 0.01)) if held_out_colour(hue, sat) else (hue, sat)


# Randomisation at strength 1 (scaled by ``randomise``): per surface a hue shift up to ±0.1 and saturation and value
# scaled by up to 2 ** ±0.5 and 2 ** ±0.4; per room a white-balance error up to 2 ** ±0.2 per channel; per view an
# exposure change up to ±0.25 stops (with the room's ±0.6 still short of the held-out 0.9) and ±0.08 per channel.
RANDOM_HUE, RANDOM_SAT_EV, RANDOM_VAL_EV = 0.1, 0.5, 0.4
RANDOM_TINT_EV = 0.2
RANDOM_VIEW_EV, RANDOM_VIEW_CHANNEL_EV = 0.25, 0.08


def jitter_colour(rng: np.random.Generator, hue: float, sat: float, val: float) -> tuple[float, float, float]:
    """A drawn surface colour perturbed by the current randomisation (unchanged, nothing drawn, when off)."""
    r = current().randomise
    if r <= 0:
        return hue, sat, val
    hue = (hue + float(rng.uniform(-RANDOM_HUE, RANDOM_HUE)) * r) % 1.0
    sat = float(np.clip(sat * 2.0 ** (float(rng.uniform(-RANDOM_SAT_EV, RANDOM_SAT_EV)) * r), 0.0, 1.0))
    val = float(np.clip(val * 2.0 ** (float(rng.uniform(-RANDOM_VAL_EV, RANDOM_VAL_EV)) * r), 0.0, 1.0))
    return hue, sat, val


def room_tint(rng: np.random.Generator) -> tuple[float, float, float]:
    """A room's per-channel white-balance gains ((1, 1, 1), nothing drawn, when randomisation is off)."""
    r = current().randomise
    if r <= 0:
        return 1.0, 1.0, 1.0
    return tuple(float(2.0 ** (g * r)) for g in rng.uniform(-RANDOM_TINT_EV, RANDOM_TINT_EV, 3))  # type: ignore


def view_gains(randomise: float, rng: np.random.Generator) -> np.ndarray:
    """float (3,) per-channel gains of one view at randomisation strength ``randomise`` (ones when 0)."""
    if randomise <= 0:
        return np.ones(3)
    ev = float(rng.uniform(-RANDOM_VIEW_EV, RANDOM_VIEW_EV)) * randomise
    return 2.0 ** (ev + rng.uniform(-RANDOM_VIEW_CHANNEL_EV, RANDOM_VIEW_CHANNEL_EV, 3) * randomise)


def exposure(rng: np.random.Generator) -> float:
    """A scene's exposure scale: 2 ** uniform(±TRAIN_EXPOSURE_EV), or beyond it in a shifted room."""
    if current().appearance_shift:
        sign = 1.0 if rng.random() < 0.5 else -1.0
        return float(2.0 ** (sign * rng.uniform(*HELD_OUT_EXPOSURE_EV)))
    return float(2.0 ** rng.uniform(-TRAIN_EXPOSURE_EV, TRAIN_EXPOSURE_EV))


def sensor(rng: np.random.Generator) -> tuple[float, float, float]:
    """(tone strength k, gamma, noise sigma in 8-bit levels) of a scene's camera."""
    if current().appearance_shift:
        k, gamma = float(rng.uniform(*HELD_OUT_TONE_K)), float(rng.uniform(*HELD_OUT_GAMMA))
        return k, gamma, float(rng.uniform(*HELD_OUT_NOISE))
    return TRAIN_TONE[0], TRAIN_TONE[1], 0.0
