"""Import scans shared by the import-rule tests: the product's folders, the modules a file imports and the
cycles of an import graph."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PRODUCT = ("model", "data_tools", "platform", "jobs")
"""The four top-level folders of the product, installed as ``sray.<folder>``."""
LAB = "lab"
"""The studies and diagnostics (``sray.lab``): may import the product; nothing in the product imports it."""


def imported_modules(path: Path, root: Path = REPO) -> list[str]:
    """Absolute module names a Python file under ``root`` imports anywhere in it (relative imports resolved;
    ``from package import name`` also counts ``package.name``, which may be a module)."""
    names = []
    package = ["sray", *path.relative_to(root).parent.parts]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else [])) \
                if node.level else node.module
            names += [base, *(f"{base}.{alias.name}" for alias in node.names)]
    return names


def plant(root: Path, files: dict[str, str]) -> None:
    """Write each ``relative path -> text`` under ``root`` (a copy of the layout a scan's own test reads)."""
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)


def cycles(graph: dict[str, set[str]]) -> list[str]:
    """Each cycle of ``graph`` found by a depth-first walk, as ``a -> b -> a``."""
    found: list[str] = []
    state: dict[str, int] = {}

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                found.append(" -> ".join(trail[trail.index(nxt):] + [node, nxt]) if nxt in trail
                             else f"{node} -> {nxt}")
            elif nxt not in state:
                visit(nxt, trail + [node])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    return found
