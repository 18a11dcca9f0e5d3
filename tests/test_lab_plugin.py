"""The lab reaches the ``sray`` command only as a plug-in: the product's parser loads the entry points of the group
``sray.commands``, and the installed lab registers ``sray lab`` there."""

from __future__ import annotations

import argparse
import importlib.metadata
import sys

import pytest

from sray.jobs import cli


def test_the_installed_lab_is_an_entry_point_that_adds_sray_lab() -> None:
    """pyproject.toml's entry point names ``sray.lab.cli:register``; the product's parser lists ``lab`` with the
    lab's commands through it."""
    entries = {e.name: e.value for e in importlib.metadata.entry_points(group=cli.PLUGIN_GROUP)}
    assert entries.get("lab") == "sray.lab.cli:register", entries
    lab = next(a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices["lab"]
    commands = next(a for a in lab._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert {"study", "ceilings", "view-weights", "recipe-step", "recipe-cards", "demo-result"} <= set(commands)


def test_the_parser_calls_each_plug_in_and_only_through_its_entry_point(monkeypatch: pytest.MonkeyPatch) -> None:
    """A plug-in's ``register`` gets the sub-command table; with no plug-in installed there is no ``lab`` command, and
    building the parser imports nothing of the lab."""
    seen: list[str] = []

    class Entry:
        name, value = "toy", "toy:register"

        def load(self):  # noqa: ANN202 - the entry point's loader
            return lambda sub: seen.append(sub.add_parser("toy").prog)

    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda group: [Entry()] if group == cli.PLUGIN_GROUP else [])
    for name in [m for m in sys.modules if m.startswith("sray.lab")]:
        monkeypatch.delitem(sys.modules, name)
    parser = cli.build_parser()
    assert seen == ["sray toy"]
    choices = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert "toy" in choices and "lab" not in choices and "bench" in choices
    assert not [m for m in sys.modules if m.startswith("sray.lab")]
    with pytest.raises(SystemExit):
        cli.main(["lab", "study", "jobs/studies/hour-recipe.yaml"])
