"""A sweep parameter, ``section.field=SPEC`` with SPEC one of ``choice(a, ...)``, ``grid(a, ...)`` (every value,
crossed with the other grids), ``uniform(lo, hi)``, ``loguniform(lo, hi)``, and the plan: every trial's values, drawn
once from a seeded generator before anything runs (a resumed sweep runs the same trials under the same keys), in
Tune's order. Listed values are parsed by the field's type through the typed ``--set`` path, so a sweep takes any
field ``sray train --set`` takes."""

from __future__ import annotations

import itertools
import math
import random
import re
from dataclasses import dataclass
from typing import Any

KINDS = ("choice", "uniform", "loguniform", "grid")
_CALL = re.compile(r"^\s*([A-Za-z_]+)\s*\((.*)\)\s*$", re.S)
_PATH = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)+$")
_BRACKETS = {"(": ")", "[": "]"}


class SpecError(ValueError):
    """A sweep spec is wrong; the message names the parameter or option and the fix, on one line."""


@dataclass(frozen=True)
class Param:
    """One swept config field and its distribution."""

    path: str
    """``section.field`` of the trial config, as ``--set`` takes it."""
    kind: str
    values: tuple[str, ...]
    """The listed values of ``choice`` and ``grid``, as written; the two bounds of a range, as written."""

    @property
    def spec(self) -> str:
        """The distribution as the user writes it, e.g. ``loguniform(1e-4, 1e-2)``."""
        return f"{self.kind}({', '.join(self.values)})"

    def draw(self, rng: random.Random) -> str | float:
        """One random value (``choice``, ``uniform``, ``loguniform``; a grid parameter is not drawn)."""
        if self.kind == "choice":
            return rng.choice(self.values)
        lo, hi = map(float, self.values)
        if self.kind == "uniform":
            return rng.uniform(lo, hi)
        if self.kind == "loguniform":
            return math.exp(rng.uniform(math.log(lo), math.log(hi)))
        raise ValueError(f"sweep parameter {self.path}: a grid parameter is enumerated, not drawn")


def split_items(text: str) -> list[str]:
    """Comma-separated items at the top level (commas inside brackets belong to an item), stripped."""
    items, depth, current = [], [], ""
    for char in text:
        if char in _BRACKETS:
            depth.append(_BRACKETS[char])
        elif depth and char == depth[-1]:
            depth.pop()
        elif char == "," and not depth:
            items.append(current.strip())
            current = ""
            continue
        current += char
    items.append(current.strip())
    return items if any(items) else []


def _number(path: str, kind: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise SpecError(f"sweep parameter {path}: {kind} bound {text!r} is not a number; "
                        f"write e.g. {kind}(1e-4, 1e-2)") from None
    if not math.isfinite(value):
        raise SpecError(f"sweep parameter {path}: {kind} bound {text!r} is not finite")
    return value


def parse_param(path: str, spec: str) -> Param:
    """The parameter ``path`` with distribution ``spec``; :class:`SpecError` naming it when either is malformed."""
    path = path.strip()
    if not _PATH.match(path):
        raise SpecError(f"sweep parameter {path!r}: expected section.field (as --set takes it), e.g. optim.lr")
    match = _CALL.match(str(spec))
    if not match or match.group(1) not in KINDS:
        raise SpecError(f"sweep parameter {path}: {spec!r} is not a distribution; write one of "
                        "choice(a,b,...), uniform(lo,hi), loguniform(lo,hi), grid(a,b,...)")
    kind, items = match.group(1), split_items(match.group(2))
    if any(not item for item in items):
        raise SpecError(f"sweep parameter {path}: {spec!r} has an empty value; separate values by single commas")
    if kind in ("choice", "grid"):
        if not items:
            raise SpecError(f"sweep parameter {path}: {kind}() lists no value; write e.g. {kind}(0.5, 1.0)")
        if len(set(items)) != len(items):
            raise SpecError(f"sweep parameter {path}: {spec!r} lists a value twice; list each value once")
        return Param(path, kind, tuple(items))
    if len(items) != 2:
        raise SpecError(f"sweep parameter {path}: {kind} takes two bounds, got {len(items)} in {spec!r}; "
                        f"write {kind}(lo, hi)")
    lo, hi = (_number(path, kind, item) for item in items)
    if not lo < hi:
        raise SpecError(f"sweep parameter {path}: {spec!r} needs lo < hi")
    if kind == "loguniform" and lo <= 0:
        raise SpecError(f"sweep parameter {path}: {spec!r} needs 0 < lo (it draws the logarithm); "
                        "use uniform(lo, hi) for a range that reaches 0")
    return Param(path, kind, tuple(items))


def parse_assignment(assignment: str) -> Param:
    """A ``section.field=SPEC`` flag (``--param``) as a :class:`Param`."""
    path, sep, spec = assignment.partition("=")
    if not sep:
        raise SpecError(f"--param {assignment!r}: expected section.field=SPEC, e.g. optim.lr=loguniform(1e-4,1e-2)")
    return parse_param(path, spec)


def check_unique(params: list[Param]) -> None:
    """:class:`SpecError` when two parameters name the same field."""
    paths = [p.path for p in params]
    for i, path in enumerate(paths):
        if path in paths[:i]:
            raise SpecError(f"sweep parameter {path}: given twice; give each field one distribution")


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
    """Trial key -> {field path: value}, ``samples`` x (product of the grid sizes) trials, draws seeded by ``seed``."""
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
