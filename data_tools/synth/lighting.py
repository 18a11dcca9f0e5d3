"""A room's lights: ceiling lamps, an optional floor lamp and window daylight, each tinted by its colour temperature
(Planck's law at three wavelengths relative to 6504 K white, half white-balanced: docs/data.md, "Appearance")."""

from __future__ import annotations

import math

import numpy as np

from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.synth import domains
from sray.data_tools.synth import fittings as fx
from sray.data_tools.synth import materials as mat
from sray.data_tools.synth.floor_plan import FloorPlan, Light
from sray.data_tools.synth.furniture import Piece, span

WAVELENGTHS_M = (610e-9, 550e-9, 465e-9)  # representative wavelengths of the red, green and blue channels
WHITE_K = 6504.0  # the colour temperature that renders white (sRGB / D65 white point)


def _planck(wavelength: float, kelvin: float) -> float:
    """Black-body spectral radiance up to a constant factor."""
    h, c, k = 6.62607e-34, 2.99792e8, 1.380649e-23
    return 1.0 / (wavelength**5 * math.expm1(h * c / (wavelength * k * kelvin)))


def kelvin_rgb(kelvin: float) -> tuple[float, float, float]:
    """Linear RGB tint (max channel 1) of a light of colour temperature ``kelvin`` (module docstring)."""
    ratio = [_planck(lam, kelvin) / _planck(lam, WHITE_K) for lam in WAVELENGTHS_M]
    return tuple(math.sqrt(r / max(ratio)) for r in ratio)  # type: ignore[return-value]


def _floor_lamp(rng: np.random.Generator, height: float) -> Piece:
    """A floor lamp: base, pole and an emissive shade (ignore-labelled: ScanNet-20 has no lamp class)."""
    s, metal = float(rng.uniform(0.14, 0.22)), mat.metal(rng)
    boxes = [span(IGNORE_ID, metal, -0.13, 0.13, -0.13, 0.13, 0.0, 0.03),
             span(IGNORE_ID, metal, -0.015, 0.015, -0.015, 0.015, 0.03, height - 0.25),
             span(IGNORE_ID, mat.lamp_glow(), -s, s, -s, s, height - 0.25, height, casts_shadow=False)]
    return Piece(boxes, 2 * s, 2 * s, height)


def _light(position: tuple[float, float, float], intensity: float, kelvin: float) -> Light:
    """A point light of colour temperature ``kelvin``."""
    return Light(position, intensity, kelvin_rgb(kelvin), kelvin)


def _low_main_light(rng: np.random.Generator, plan: FloorPlan) -> None:
    """The held-out main light of a shifted room: low (below ``domains.LOW_LIGHT_TOP``) by a wall, shadows cast up."""
    wall = int(rng.integers(4))
    x, y, _ = plan.wall_pose(wall, float(rng.uniform(0.3, plan.wall_length(wall) - 0.3)), 0.0, 0.25)
    plan.lights.append(_light((x, y, float(rng.uniform(0.3, domains.LOW_LIGHT_TOP))), float(rng.uniform(1.5, 2.5)),
                              float(rng.uniform(*domains.HELD_OUT_KELVIN))))


def add_lights(rng: np.random.Generator, plan: FloorPlan) -> None:
    """Ceiling lamps (1-4 by floor area) with a point light under each (the first casts shadows), maybe a floor lamp,
    daylight by up to two windows; a shifted room: held-out lamp colours, a low main light first."""
    lx, ly, h = plan.size
    shifted = domains.current().appearance_shift
    if shifted:
        _low_main_light(rng, plan)
    base_k = float(rng.uniform(*domains.HELD_OUT_KELVIN)) if shifted else float(rng.uniform(2700.0, 6500.0))
    n = int(np.clip(round(lx * ly / 9.0 + rng.uniform(-0.5, 0.5)), 1, 4))
    cols = 1 if n == 1 else 2
    rows = math.ceil(n / cols)
    for i in range(n):
        fx_, fy_ = ((i % cols) + 0.5) / cols, ((i // cols) + 0.5) / rows
        x = lx * fx_ + float(rng.uniform(-0.25, 0.25)) if lx >= ly else lx * fy_ + float(rng.uniform(-0.25, 0.25))
        y = ly * fy_ + float(rng.uniform(-0.25, 0.25)) if lx >= ly else ly * fx_ + float(rng.uniform(-0.25, 0.25))
        x, y = float(np.clip(x, 0.4, lx - 0.4)), float(np.clip(y, 0.4, ly - 0.4))
        plan.add(fx.ceiling_lamp(rng, h), x, y, 0.0, occupies_floor=False)
        kelvin = base_k + float(rng.uniform(-300.0, 300.0))
        if shifted:
            kelvin = float(np.clip(kelvin, *domains.HELD_OUT_KELVIN))
        plan.lights.append(_light((x, y, h - 0.35), float(rng.uniform(1.6, 3.4)) / n ** 0.5, kelvin))
    if rng.random() < 0.4:
        lamp = _floor_lamp(rng, float(rng.uniform(1.4, 1.75)))
        for wall in [int(w) for w in rng.permutation(4)]:
            s = plan.try_wall(rng, lamp, wall, gap=0.05, tries=8)
            if s is not None:
                x, y, _ = plan.wall_pose(wall, s, lamp.depth, 0.05)
                plan.lights.append(_light((x, y, lamp.height - 0.12), float(rng.uniform(0.5, 1.2)),
                                          float(rng.uniform(2400.0, 3200.0))))
                break
    for x, y, z in plan.windows[:2]:
        plan.lights.append(_light((x, y, z), float(rng.uniform(0.3, 1.0)), float(rng.uniform(6500.0, 10000.0))))
