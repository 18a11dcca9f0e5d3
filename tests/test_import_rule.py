"""The import rule (ARCHITECTURE §1): ``model`` imports nothing of ours, ``data_tools`` no model/platform/jobs."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FORBIDDEN = {
    "model": ("sray.data_tools", "sray.platform", "sray.jobs"),
    "data_tools": ("sray.model", "sray.platform", "sray.jobs"),
}
"""Per folder: the sray packages its modules may not import (at module level or inside a function)."""


def imported_modules(path: Path) -> list[str]:
    """Absolute module names a Python file imports anywhere in it."""
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append(node.module)
    return names


@pytest.mark.parametrize("folder", sorted(FORBIDDEN))
def test_folder_keeps_the_import_rule(folder: str) -> None:
    """No module under ``folder`` (sub-packages included) imports a package the rule forbids it."""
    files = sorted((REPO / folder).rglob("*.py"))
    assert files, folder
    broken = [f"{path.relative_to(REPO)} imports {name}" for path in files for name in imported_modules(path)
              if any(name == bad or name.startswith(bad + ".") for bad in FORBIDDEN[folder])]
    assert not broken, "\n".join(broken)
