"""A sweep as asked for: its options, its spec file and the request built from both. A spec file's keys are
``sray sweep``'s own flags (``recipe``, ``data``, ``set``, ``params`` and every option; ``jobs/sweeps/demo_lr_sem.yaml``
is one); flags given on the command line win over the file's values, and what neither gives keeps its default."""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from sray.platform.config.train_config import TrainConfig
from sray.platform.sweep.spec import Param, SpecError, check_unique, parse_param

MODES = ("max", "min")
"""Whether a higher or a lower value of the metric is better."""
SCHEDULERS = ("asha", "none")
"""``asha``: asynchronous successive halving on the training step; ``none``: every trial runs its budget."""


@dataclass
class SweepOptions:
    """Everything about a sweep besides its parameters and its starting config."""

    samples: int = 1
    """Draws of the random parameters (each crossed with every grid combination)."""
    seeds: int = 0
    """Seeds per point: ``run.seed`` becomes grid(0, ..., seeds - 1); 0 keeps the config's seed."""
    seed: int = 0
    """Seed of the random parameters' draws (the same spec and seed give the same trials)."""
    metric: str = "val/miou"
    """The validation metric trials are compared by (``val/*`` or ``zeroshot/*``, as the training job logs it)."""
    mode: str = "max"
    scheduler: str = "asha"
    grace: int = 0
    """ASHA: steps before a trial can be stopped; 0 = ``run.ckpt_every`` (where a training job first reports)."""
    reduction_factor: float = 3.0
    """ASHA: about 1 in this many trials continues at each rung (rungs at grace x factor^k steps)."""
    max_concurrent: int = 0
    """Trials running at once; 0 = as many as the cluster fits at once (at least 1)."""
    steps: int = 0
    """Budget per trial in optimiser steps (``optim.steps``); 0 = the config's."""
    cpu_seconds: float = 0.0
    """Budget per trial in CPU seconds summed over its ranks (``optim.cpu_seconds``); 0 = the config's."""
    minutes: float = 0.0
    """Budget per trial in wall-clock minutes of training (then it checkpoints and ends); 0 = none."""


def check_options(options: SweepOptions) -> None:
    """:class:`SpecError` naming the first option out of range and the fix."""
    o = options
    problems = [
        (o.mode not in MODES, f"--mode {o.mode!r}: use one of {', '.join(MODES)}"),
        (o.scheduler not in SCHEDULERS, f"--scheduler {o.scheduler!r}: use one of {', '.join(SCHEDULERS)}"),
        (o.samples < 1, f"--samples {o.samples}: at least 1"),
        (o.seeds < 0, f"--seeds {o.seeds}: 0 (keep the config's seed) or more"),
        (o.grace < 0, f"--grace {o.grace}: 0 (the checkpoint interval) or a positive number of steps"),
        (o.reduction_factor <= 1, f"--reduction-factor {o.reduction_factor:g}: must be above 1, e.g. 3"),
        (o.max_concurrent < 0, f"--max-concurrent {o.max_concurrent}: 0 (as many as fit) or more"),
        (o.steps < 0, f"--steps {o.steps}: 0 (the config's optim.steps) or more"),
        (o.cpu_seconds < 0, f"--cpu-seconds {o.cpu_seconds:g}: 0 (off) or more"),
        (o.minutes < 0, f"--minutes {o.minutes:g}: 0 (off) or more"),
        (not o.metric.strip(), "--metric: name the validation metric to compare trials by, e.g. val/miou"),
    ]
    for bad, message in problems:
        if bad:
            raise SpecError(message)


@dataclass
class SweepRequest:
    """A new sweep, as the command line (or a test) asks for it, before any check."""

    name: str
    """Unique name: the sweep's folder under ``out`` and its parent run's name."""
    out: Path
    base: TrainConfig
    """The config every trial starts from (a recipe with the fixed overrides)."""
    params: list[Param]
    options: SweepOptions


@dataclass
class SpecFile:
    """What a spec file holds, parsed; option values are checked by :func:`merge_options`."""

    recipe: str | None = None
    """Recipe the trials start from (None: the command's default)."""
    data: str | None = None
    """``data.shards`` of the trials (None: the recipe's)."""
    sets: list[str] = field(default_factory=list)
    """Fixed ``section.field=value`` overrides applied before the swept values."""
    params: list[Param] = field(default_factory=list)
    options: dict[str, Any] = field(default_factory=dict)
    """Options of :class:`SweepOptions` the file gives."""


OPTION_NAMES = tuple(f.name for f in dataclasses.fields(SweepOptions))
"""Keys of :class:`SweepOptions`, as spec-file keys (flags: ``--max-concurrent`` for ``max_concurrent``)."""
FILE_KEYS = ("recipe", "data", "set", "params", *OPTION_NAMES)


def _sets(where: Path, value: Any) -> list[str]:
    if isinstance(value, dict):
        return [f"{k}={v}" for k, v in value.items()]
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return list(value)
    raise SpecError(f"{where}: 'set' must map section.field to a value (or list section.field=value strings)")


def _params(where: Path, value: Any) -> list[Param]:
    if not isinstance(value, dict) or not value:
        raise SpecError(f"{where}: 'params' must map each swept section.field to a distribution, "
                        "e.g. optim.lr: loguniform(1e-4, 1e-2)")
    params = []
    for path, spec in value.items():
        if not isinstance(spec, str):
            raise SpecError(f"sweep parameter {path}: {spec!r} is a fixed value; put it under 'set:' or write "
                            f"a distribution, e.g. choice({spec})")
        params.append(parse_param(str(path), spec))
    return params


def read_yaml_keys(path: Path, what: str, keys: tuple[str, ...]) -> dict[str, Any]:
    """The YAML mapping of ``keys`` in ``path`` (a ``what``); :class:`SpecError` naming the file and what is wrong."""
    try:
        raw = yaml.safe_load(Path(path).read_text())
    except OSError as e:
        raise SpecError(f"{path}: cannot read the {what} ({e.strerror})") from None
    except yaml.YAMLError as e:
        raise SpecError(f"{path}: not valid YAML ({str(e).splitlines()[0]})") from None
    if not isinstance(raw, dict):
        raise SpecError(f"{path}: a {what} is a mapping of keys ({', '.join(keys)})")
    unknown = sorted(set(raw) - set(keys))
    if unknown:
        raise SpecError(f"{path}: unknown key {unknown[0]!r}; keys: {', '.join(keys)}")
    return raw


def load_spec_file(path: Path) -> SpecFile:
    """Parse a YAML spec file; :class:`SpecError` naming the file and the key at fault."""
    path = Path(path)
    raw = read_yaml_keys(path, "sweep spec", FILE_KEYS)
    spec = SpecFile(recipe=raw.get("recipe"), data=raw.get("data"), sets=_sets(path, raw.get("set", {})),
                    params=_params(path, raw["params"]) if "params" in raw else [],
                    options={k: raw[k] for k in OPTION_NAMES if k in raw})
    check_unique(spec.params)
    return spec


def _typed(name: str, kind: Any, value: Any) -> Any:
    """``value`` as the option's type (an int stays an int, a float may be written as an int)."""
    ok = {int: isinstance(value, int) and not isinstance(value, bool),
          float: isinstance(value, (int, float)) and not isinstance(value, bool),
          str: isinstance(value, str)}[kind]
    if not ok:
        raise SpecError(f"option {name}: {value!r} is not a{'n' if kind is int else ''} {kind.__name__}")
    return kind(value)


def merge_options(from_file: dict[str, Any], from_flags: dict[str, Any]) -> SweepOptions:
    """The sweep's options: defaults, then the file's values, then the flags given (None = not given); checked."""
    hints = typing.get_type_hints(SweepOptions)
    given = from_file | {k: v for k, v in from_flags.items() if v is not None}
    options = SweepOptions(**{k: _typed(k, hints[k], v) for k, v in given.items()})
    check_options(options)
    return options
