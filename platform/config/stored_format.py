"""Reading a stored config (a job's ``config.json``, a checkpoint's ``config``, a sweep's base) back into its typed
dataclass, today's format only: another ``format_version`` is refused in one line naming ``sray migrate``
(``sray.platform.migrate``), which converts it once; an unknown field is refused by name."""

from __future__ import annotations

import dataclasses
import typing
from typing import Any

CONFIG_VERSION = 3
"""Format of stored configs: 1 (no ``format_version``; sray up to 7734061, flat ``data.val_*``), 2 (up to 7966ddf,
nested ``held_out``), 3 (without the fields removed since, ``sray.platform.migrate.config_formats``)."""
VERSION_KEY = "format_version"
"""Key of the format version in a stored config dict."""


class OutdatedFormat(ValueError):
    """A stored artifact written by an earlier sray: ``sray migrate PATH`` converts it."""


def outdated(what: str, found: Any, expected: Any) -> OutdatedFormat:
    """The one-line refusal of an artifact in format ``found`` where this sray reads ``expected``."""
    return OutdatedFormat(f"{what} is in format {found}, written by an earlier sray (this one reads {expected}); "
                          "convert it once with `sray migrate PATH`")


def from_plain(cls: type, d: dict[str, Any], where: str) -> Any:
    """``cls`` from its ``dataclasses.asdict`` form ``d``, nested sections included, lists as tuples where typed so;
    ValueError names a field of ``d`` that ``cls`` lacks (``where``: the section's dotted name)."""
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(d) - names)
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {', '.join(unknown)}; fields: {', '.join(sorted(names))}")
    values = {}
    for name, value in d.items():
        kind = hints[name]
        if dataclasses.is_dataclass(kind) and isinstance(value, dict):
            value = from_plain(kind, value, f"{where}.{name}")
        elif typing.get_origin(kind) is tuple and isinstance(value, list):
            value = tuple(value)
        values[name] = value
    return cls(**values)
