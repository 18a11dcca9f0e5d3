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

from sray.platform.finetune.methods import semantic_nerf_method, sray_method, sray_rgbd_method, transfer_method
from sray.platform.finetune.methods.method import Method

METHODS: dict[str, Method] = {m.name: m for m in (sray_method.METHOD, semantic_nerf_method.METHOD,
                                                  sray_rgbd_method.METHOD, transfer_method.METHOD)}
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


def reads_depth(name: str) -> bool:
    """Whether the registered method ``name`` reads the source views' depth and is not a depth twin (``2d-transfer``):
    one that S-Ray given the same depth must stand beside."""
    method = get_method(name)
    return method.inputs == "rgbd" and not method.given_depth_of


def with_depth_twins(methods: list[str], checkpoint_inputs: str = "rgb") -> list[str]:
    """``methods`` (registered names, each once, in order) with every registered depth twin (``given_depth_of``)
    placed just before the first method that reads depth (:func:`reads_depth`), when one is listed. A checkpoint that
    reads the depth already (``checkpoint_inputs == "rgbd"``) makes each twin its own method (``sray-rgbd`` ->
    ``sray``, listed once)."""
    names = list(dict.fromkeys(methods))
    first = next((i for i, name in enumerate(names) if reads_depth(name)), None)
    if first is not None:
        twins = [name for name, m in METHODS.items() if m.given_depth_of and name not in names]
        names[first:first] = twins
    if checkpoint_inputs == "rgbd":
        names = list(dict.fromkeys(METHODS[n].given_depth_of or n for n in names))
    return names
