"""The method registry: every per-scene method by name, registered at import so Ray workers know them (no torch)."""

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
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; use one of {', '.join(METHODS)}")
    return METHODS[name]


def method_names() -> list[str]:
    """Names of every registered method, in registration order."""
    return list(METHODS)


def eval_method_names() -> list[str]:
    """Names of the registered methods ``sray eval`` can score (those with an ``eval_model`` builder)."""
    return [name for name, m in METHODS.items() if m.eval_model is not None]


def reads_depth(name: str) -> bool:
    """Whether method ``name`` reads the source depth and is not a depth twin (``2d-transfer``)."""
    method = get_method(name)
    return method.inputs == "rgbd" and not method.given_depth_of


def with_depth_twins(methods: list[str], checkpoint_inputs: str = "rgb") -> list[str]:
    """``methods`` once each, twins before the first depth reader; an RGB-D checkpoint's twins become their base."""
    names = list(dict.fromkeys(methods))
    first = next((i for i, name in enumerate(names) if reads_depth(name)), None)
    if first is not None:
        names[first:first] = [name for name, m in METHODS.items() if m.given_depth_of and name not in names]
    if checkpoint_inputs == "rgbd":
        names = list(dict.fromkeys(METHODS[n].given_depth_of or n for n in names))
    return names
