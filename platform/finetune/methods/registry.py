"""The method registry: every per-scene method a fleet runs, by name.

``sray finetune-fleet --methods`` and ``sray eval --method`` take their choices from :data:`METHODS`, the fleet
validates its request against it, a fleet task builds its learner through it, and the charts and artifact loaders
look methods up here: nothing else lists the methods. Like the reader registry, this imports no
torch: a method module imports its learner only when the method is built.

Adding a method: a :class:`~sray.platform.finetune.methods.method.Method` record (see ``sray_method.py``)
passed to :func:`register_method`; built-in methods are registered below, at import, so that Ray
workers know them too (a method registered at run time serves fleet tasks in that process only).
"""

from __future__ import annotations

from sray.platform.finetune.methods import semantic_nerf_method, sray_method, transfer_method
from sray.platform.finetune.methods.method import Method

METHODS: dict[str, Method] = {m.name: m for m in (sray_method.METHOD, semantic_nerf_method.METHOD,
                                                  transfer_method.METHOD)}
"""Every known per-scene method by name, in chart and table order."""


def register_method(method: Method) -> Method:
    """Add (or replace) ``method`` under its name; returns it."""
    METHODS[method.name] = method
    return method


def get_method(name: str) -> Method:
    """The registered method ``name``; ValueError names the known methods otherwise."""
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(f"unknown method {name!r}; use one of {', '.join(METHODS)}") from None


def method_names() -> list[str]:
    """Names of every registered method, in registration order."""
    return list(METHODS)


def eval_method_names() -> list[str]:
    """Names of the registered methods ``sray eval`` can score (those with an ``eval_model`` builder)."""
    return [name for name, m in METHODS.items() if m.eval_model is not None]
