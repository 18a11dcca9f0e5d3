"""Nested configs (dataclasses, dicts, lists) flattened into MLflow params with dotted keys."""

from __future__ import annotations

import dataclasses
import enum
import logging
import re
from collections.abc import Mapping
from typing import Any

log = logging.getLogger(__name__)

MAX_PARAM_VALUE = 6000
"""MLflow 3.17's limit on a param value's length (``mlflow.utils.validation.MAX_PARAM_VAL_LENGTH``)."""
MAX_KEY_LENGTH = 250
_BAD_KEY_CHARS = re.compile(r"[^A-Za-z0-9_\-./ ]")
"""Characters MLflow rejects in keys (its limit on their length: :data:`MAX_KEY_LENGTH`)."""
TRUNCATION_MARKER = "...[truncated]"
"""Suffix of a param value cut to :data:`MAX_PARAM_VALUE` characters."""


def _leaf_text(value: Any) -> str:
    """Text of one param value: enums by value, lists of scalars as ``[a, b]``, the rest by ``str``."""
    if isinstance(value, enum.Enum):
        return str(value.value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_leaf_text(v) for v in value) + "]"
    return str(value)


def _is_container(value: Any) -> bool:
    return (dataclasses.is_dataclass(value) and not isinstance(value, type)) or isinstance(value, Mapping)


def flatten_config(obj: Any, prefix: str = "") -> dict[str, Any]:
    """Nested dataclasses/dicts -> {dotted key: leaf}; lists of containers get index keys, lists of scalars stay
    whole: ``{"model": {"tau": 0.7}, "views": [1, 2]}`` -> ``{"model.tau": 0.7, "views": [1, 2]}``."""
    if not _is_container(obj):
        return {prefix or "value": obj}
    out: dict[str, Any] = {}
    items = (obj.items() if isinstance(obj, Mapping)
             else [(f.name, getattr(obj, f.name)) for f in dataclasses.fields(obj)])
    for name, value in items:
        key = f"{prefix}.{name}" if prefix else str(name)
        if _is_container(value):
            out.update(flatten_config(value, key))
        elif isinstance(value, (list, tuple)) and any(_is_container(v) for v in value):
            for i, item in enumerate(value):
                out.update(flatten_config(item, f"{key}.{i}"))
        else:
            out[key] = value
    return out


def sanitize_key(key: str) -> str:
    """A key MLflow accepts: disallowed characters become ``_``; ValueError when it is too long."""
    clean = _BAD_KEY_CHARS.sub("_", key)
    if len(clean) > MAX_KEY_LENGTH:
        raise ValueError(f"MLflow key {key[:60]!r}... is {len(clean)} characters; the limit is {MAX_KEY_LENGTH}")
    return clean


def to_params(obj: Any) -> dict[str, str]:
    """Flattened, MLflow-valid params: strings, over-long ones cut (:data:`TRUNCATION_MARKER`) with a warning."""
    params: dict[str, str] = {}
    for key, value in flatten_config(obj).items():
        text = _leaf_text(value)
        if len(text) > MAX_PARAM_VALUE:
            log.warning("MLflow param %r has %d characters, over the limit of %d; logged truncated (log the "
                        "full config as an artifact)", key, len(text), MAX_PARAM_VALUE)
            text = text[: MAX_PARAM_VALUE - len(TRUNCATION_MARKER)] + TRUNCATION_MARKER
        params[sanitize_key(key)] = text
    return params
