"""A stored training config of an earlier format (``stored_format.CONFIG_VERSION``), as a plain dict, converted to
today's. Format 1 also covers the older layouts 7734061 still read: ``aug_<field>`` flat in the data section, runtime
settings in the model section, fault settings in the run section. A removed field (a lever that lost) is dropped where
it holds the value at which it changed nothing; any other value is refused by name, with the last commit that had it."""

from __future__ import annotations

import copy
from typing import Any

from sray.platform.config.stored_format import CONFIG_VERSION, VERSION_KEY

REMOVED_FIELDS: dict[str, tuple[Any, str]] = {
    **{path: (value, "7734061") for path, value in (
        ("optim.ema_decay", 0.0), ("optim.weight_decay", 0.0), ("optim.lr_decay_start", "run"),
        ("data.ray_balance", 0.0), ("model.encoder_norm", "instance"), ("model.weight_map", "radial"),
        ("model.weight_inputs", "view"), ("model.ffn_mult", 0), ("model.density_activation", "softplus"))},
    **{path: (value, "7966ddf") for path, value in (
        ("model.lambda_depth", 0.0), ("model.weight_margin", 1e-3), ("data.aug.query_crop", 0.0))}}
"""Removed field -> (the value at which it changed nothing, the last commit that had it)."""

RUNTIME_FIELDS = ("impl", "chunk", "train_piece")
"""Fields of the ``runtime`` section that format 1's oldest configs held in the model section."""
VALIDATION_FIELDS = {"val_downscale": "stride", "val_render": "render", "val_fast_confidence": "fast_confidence"}
"""Format 1's flat validation settings -> their field in ``data.held_out``."""
MOVED_PATHS = {**{f"data.{old}": f"data.held_out.{new}" for old, new in VALIDATION_FIELDS.items()},
               **{f"model.{name}": f"runtime.{name}" for name in RUNTIME_FIELDS}}
"""Dotted field paths of format 1 -> today's (for a sweep's parameters)."""


class MigrationRefused(ValueError):
    """An artifact ``sray migrate`` cannot convert (its message is the one line the command prints)."""


def refuse_unless_noop(path: str, value: Any, where: str, removed: dict[str, tuple[Any, str]] = REMOVED_FIELDS) -> None:
    """MigrationRefused (``where``, field, commit to use) unless ``value`` of removed ``path`` is a no-op."""
    noop, commit = removed[path]
    if value != noop:
        raise MigrationRefused(f"{where}: {path} is {value!r}, a setting removed from sray (a lever that lost); this "
                               f"sray cannot reproduce it: use commit {commit} for this artifact")


def drop_removed(d: dict[str, Any], removed: dict[str, tuple[Any, str]], where: str) -> None:
    """Remove every dotted path of ``removed`` that the nested dict ``d`` holds (:func:`refuse_unless_noop`)."""
    for path in removed:
        *sections, name = path.split(".")
        owner = d
        for section in sections:
            owner = owner.get(section, {})
        if name in owner:
            refuse_unless_noop(path, owner.pop(name), where, removed)


def train_config_today(d: dict[str, Any], where: str) -> dict[str, Any]:
    """Today's plain form of the stored training config ``d`` of an earlier format (``where``: its file)."""
    out = copy.deepcopy(d)
    if out.pop(VERSION_KEY, 1) == 1:
        model, data, run = (out.setdefault(name, {}) for name in ("model", "data", "run"))
        runtime = out.setdefault("runtime", {})
        for name in RUNTIME_FIELDS:
            if name in model:
                runtime.setdefault(name, model.pop(name))
        aug = data.setdefault("aug", {})
        for key in [k for k in data if k.startswith("aug_")]:
            aug.setdefault(key.removeprefix("aug_"), data.pop(key))
        for name in ("fail_at_step", "nan_at_step", "stop_after_step"):  # replaced by the SRAY_FAULTS hook
            run.pop(name, None)
        held_out = {"n_source": 0, "stride": 2, "render": "fast", "fast_stride": 1, "fast_confidence": 0.9}
        data["held_out"] = held_out | {new: data.pop(old) for old, new in VALIDATION_FIELDS.items() if old in data}
    drop_removed(out, REMOVED_FIELDS, where)
    return {VERSION_KEY: CONFIG_VERSION, **out}


def today_path(path: str) -> str | None:
    """Today's dotted path of the stored field ``path`` (None for a removed field)."""
    if path in REMOVED_FIELDS:
        return None
    if path.startswith("data.aug_"):
        return "data.aug." + path.removeprefix("data.aug_")
    return MOVED_PATHS.get(path, path)
