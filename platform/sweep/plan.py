"""A sweep's plan: every trial's parameter values, drawn once from a seeded generator and stored before anything
runs, so a resumed sweep runs the same trials under the same keys. Order: the samples in turn, each crossed with
every grid combination (first grid value first), as Tune orders ``num_samples`` and ``grid_search``.
"""

from __future__ import annotations

import itertools
import random
from typing import Any

from sray.platform.sweep.spec import Param, SpecError

SEED_FIELD = "run.seed"
"""The training config's seed: ``--seeds N`` makes it a grid parameter over 0..N-1."""


def trial_keys(count: int) -> list[str]:
    """``t000``, ``t001``, ...: one key per trial, zero-padded to at least three digits."""
    width = max(3, len(str(count - 1)))
    return [f"t{i:0{width}d}" for i in range(count)]


def with_seeds(params: list[Param], seeds: int) -> list[Param]:
    """``params`` plus ``run.seed=grid(0..seeds-1)`` (``seeds`` 0: unchanged); SpecError when it is swept already."""
    if seeds <= 0:
        return list(params)
    if any(p.path == SEED_FIELD for p in params):
        raise SpecError(f"sweep parameter {SEED_FIELD}: given and --seeds {seeds} too; keep one of them")
    return [*params, Param(SEED_FIELD, "grid", tuple(str(s) for s in range(seeds)))]


def build_plan(params: list[Param], samples: int, seed: int) -> dict[str, dict[str, Any]]:
    """Trial key -> {field path: value}, ``samples`` x (product of the grid sizes) trials; ``seed`` seeds the
    draws, so the same spec gives the same plan."""
    if samples < 1:
        raise SpecError(f"--samples {samples}: at least 1 sample is needed")
    grids = [p for p in params if p.kind == "grid"]
    drawn = [p for p in params if p.kind != "grid"]
    rng = random.Random(seed)
    points: list[dict[str, Any]] = []
    for _ in range(samples):
        for combo in itertools.product(*(p.values for p in grids)):
            values = {p.path: p.draw(rng) for p in drawn} | dict(zip((p.path for p in grids), combo))
            points.append({p.path: values[p.path] for p in params})
    return dict(zip(trial_keys(len(points)), points))
