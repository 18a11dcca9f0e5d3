"""Format 1 -> 2 of a stored training config: every layout sray wrote up to commit 7734061, as plain dicts.

Format 1 covers, besides 7734061's own layout (``data.val_*`` and ``finetune.eval_*`` flat, no ``format_version``),
the older ones that commit still read: augmentation settings flat in the data section (``aug_<field>``), runtime
settings in the model section, and the fault settings of the run section that the ``SRAY_FAULTS`` hook replaced.

Fields removed since (levers that lost) are dropped where they hold the value that changed nothing (then the
config trains and renders exactly as before); any other value cannot be reproduced by this sray and is refused by
name, with the last commit that had it.
"""

from __future__ import annotations

import copy
from typing import Any

from sray.platform.config.stored_format import CONFIG_VERSION, VERSION_KEY

LAST_COMMIT = "7734061"
"""The last commit whose code wrote format 1 (and had every removed field)."""

REMOVED_FIELDS: dict[str, Any] = {"optim.ema_decay": 0.0, "optim.weight_decay": 0.0, "optim.lr_decay_start": "run",
                                  "data.ray_balance": 0.0, "model.encoder_norm": "instance",
                                  "model.weight_map": "radial", "model.weight_inputs": "view",
                                  "model.ffn_mult": 0, "model.density_activation": "softplus"}
"""Field removed after format 1 -> the value at which it changed nothing (its default)."""

RETIRED_RUN_FIELDS = ("fail_at_step", "nan_at_step", "stop_after_step")
"""Run settings of injected faults, replaced by the ``SRAY_FAULTS`` hook before 7734061: never part of a result."""

RUNTIME_FIELDS = ("impl", "chunk", "train_piece")
"""Fields of the ``runtime`` section that older configs held in the model section."""

VALIDATION_FIELDS = {"val_downscale": "stride", "val_render": "render", "val_fast_confidence": "fast_confidence"}
"""Format 1's flat validation settings -> their field in ``data.held_out``."""

MOVED_PATHS = {**{f"data.{old}": f"data.held_out.{new}" for old, new in VALIDATION_FIELDS.items()},
               **{f"model.{name}": f"runtime.{name}" for name in RUNTIME_FIELDS}}
"""Dotted field paths of format 1 -> today's (for a sweep's parameters)."""


class MigrationRefused(ValueError):
    """An artifact ``sray migrate`` cannot convert (its message is the one line the command prints)."""


def removed_value(path: str, value: Any, where: str) -> None:
    """MigrationRefused unless ``value`` of the removed field ``path`` is the one that changed nothing."""
    if value != REMOVED_FIELDS[path]:
        raise MigrationRefused(f"{where}: {path} is {value!r}, a setting removed from sray (a lever that lost); this "
                               f"sray cannot reproduce it: use commit {LAST_COMMIT} for this artifact")


def train_config_v2(d: dict[str, Any], where: str) -> dict[str, Any]:
    """Today's (format 2) plain form of the format-1 training config ``d``; MigrationRefused names a removed setting
    it cannot keep. ``where``: the file, for messages."""
    out = copy.deepcopy(d)
    model, data = out.setdefault("model", {}), out.setdefault("data", {})
    runtime = out.setdefault("runtime", {})
    for name in RUNTIME_FIELDS:
        if name in model:
            runtime.setdefault(name, model.pop(name))
    aug = data.setdefault("aug", {})
    for key in [k for k in data if k.startswith("aug_")]:
        aug.setdefault(key.removeprefix("aug_"), data.pop(key))
    run = out.setdefault("run", {})
    for name in RETIRED_RUN_FIELDS:
        run.pop(name, None)
    held_out = {"n_source": 0, "stride": 2, "render": "fast", "fast_stride": 1, "fast_confidence": 0.9}
    for old, new in VALIDATION_FIELDS.items():
        if old in data:
            held_out[new] = data.pop(old)
    data["held_out"] = held_out
    for path in REMOVED_FIELDS:
        section, name = path.split(".")
        if name in out.get(section, {}):
            removed_value(path, out[section].pop(name), where)
    return {VERSION_KEY: CONFIG_VERSION, **out}


def today_path(path: str) -> str | None:
    """Today's dotted path of the format-1 field ``path`` (None for a removed field)."""
    if path in REMOVED_FIELDS:
        return None
    if path.startswith("data.aug_"):
        return "data.aug." + path.removeprefix("data.aug_")
    return MOVED_PATHS.get(path, path)
