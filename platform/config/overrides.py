"""``--set section.field=value`` on nested config dataclasses, every command's override: the value is parsed as the
field's type; an unknown name is refused with the valid ones; a value the config's checks reject is rolled back."""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Callable
from typing import Any


def parse_value(kind: Any, raw: str, assignment: str) -> Any:
    """Parse ``raw`` as the annotated type ``kind``; ValueError names the assignment."""
    args = typing.get_args(kind)
    origin = typing.get_origin(kind)
    if type(None) in args:  # X | None
        if raw.lower() in ("none", "null", ""):
            return None
        return parse_value(next(a for a in args if a is not type(None)), raw, assignment)
    if origin in (tuple, list):
        items = [parse_value(args[0], x.strip(), assignment) for x in raw.strip("()[] ").split(",") if x.strip()]
        return tuple(items) if origin is tuple else items
    if kind is bool:
        if raw.lower() not in ("true", "false", "1", "0", "yes", "no"):
            raise ValueError(f"--set {assignment!r}: {raw!r} is not a bool (true/false)")
        return raw.lower() in ("true", "1", "yes")
    try:
        return kind(raw)
    except ValueError:
        raise ValueError(f"--set {assignment!r}: {raw!r} is not a valid {kind.__name__}") from None


def _sections(node: Any) -> list[str]:
    """Names of the fields of ``node`` that are themselves config sections (dataclasses)."""
    return [f.name for f in dataclasses.fields(node) if dataclasses.is_dataclass(getattr(node, f.name))]


def set_field(cfg: Any, assignment: str, example: str, validate: Callable[[], None]) -> None:
    """Apply ``[section.]field=value`` to ``cfg`` and ``validate()``, restoring the old value on ValueError (``example``
    is shown without ``=``); frozen sections on the path are replaced by copies, up to the first mutable one."""
    if "=" not in assignment:
        raise ValueError(f"--set {assignment!r}: expected [section.]field=value, e.g. {example}")
    path, raw = (part.strip() for part in assignment.split("=", 1))
    parts = path.split(".")
    chain: list[Any] = [cfg]
    for part in parts[:-1]:
        child = getattr(chain[-1], part, None)
        if not dataclasses.is_dataclass(child):
            raise ValueError(f"--set {assignment!r}: no section {part!r}; sections: {', '.join(_sections(chain[-1]))}")
        chain.append(child)
    target, name = chain[-1], parts[-1]
    where, sections = f"--set {assignment!r}: no field {name!r} in {type(target).__name__}", _sections(target)
    if name in sections:
        inner = sorted(f.name for f in dataclasses.fields(getattr(target, name)))
        raise ValueError(f"{where}; {name!r} is a section: set its fields, {path}.<field> with <field> one of "
                         f"{', '.join(inner)}")
    fields = {f.name for f in dataclasses.fields(target)} - set(sections)
    if name not in fields:
        raise ValueError(f"{where}; fields: {', '.join(sorted(fields))}")
    value = parse_value(typing.get_type_hints(type(target))[name], raw, assignment)
    depth = len(parts) - 1
    while depth > 0 and type(chain[depth]).__dataclass_params__.frozen:
        value = dataclasses.replace(chain[depth], **{parts[depth]: value})
        depth -= 1
    owner, key = chain[depth], parts[depth]
    previous = getattr(owner, key)
    setattr(owner, key, value)
    try:
        validate()
    except ValueError:
        setattr(owner, key, previous)
        raise


def apply_settings(cfg: Any, flags: dict[str, Any], assignments: list[str],
                   apply: Callable[[Any, str], None]) -> None:
    """Apply a command's flags (``path -> value``, None = not given), then its ``--set`` assignments."""
    for assignment in [f"{path}={value}" for path, value in flags.items() if value is not None] + list(assignments):
        apply(cfg, assignment)
