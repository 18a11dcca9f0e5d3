"""The docs follow the code: every module path and dotted ``sray.…`` name they mention exists."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = sorted([REPO / "README.md", REPO / "CONTRIBUTING.md", *(REPO / "docs").glob("*.md"),
               *(REPO / "docs" / "studies").glob("*.md")])
FOLDERS = ("model", "data_tools", "platform", "jobs", "lab", "tests", "docker", "docs")
PATH = re.compile(r"(?<![\w/.-])((?:%s)/[\w/.-]*\w)" % "|".join(FOLDERS))
DOTTED = re.compile(r"(?<![\w.])(sray\.(?:model|data_tools|platform|jobs|lab)(?:\.\w+)*)")


def _existing_module(dotted: str) -> bool:
    """True if ``dotted`` names an importable module, or an attribute path inside one."""
    parts = dotted.split(".")
    for cut in range(len(parts), 1, -1):
        name = ".".join(parts[:cut])
        try:
            if importlib.util.find_spec(name) is not None:
                return True
        except ModuleNotFoundError:
            continue
    return False


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_mentioned_paths_and_modules_exist(doc: Path) -> None:
    text = doc.read_text()
    missing = [p for p in PATH.findall(text) if not (REPO / p.rstrip(".")).exists() and "*" not in p
               and not p.startswith(("docs/benchmarks/",))]
    missing += [d for d in DOTTED.findall(text) if not _existing_module(d)]
    assert not missing, f"{doc.name} mentions what does not exist: {sorted(set(missing))}"


MACHINE_FOLDER = re.compile(r"(?<![\w.-])/(?:tmp|work|home|root|Users|private/var)/[\w.-]+")


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_no_line_names_one_machines_absolute_folder(doc: Path) -> None:
    """Commands and notes name repository-relative paths or placeholders (``OUT/…``), never a folder of the
    machine that wrote them; the benchmarks' stored data neither."""
    texts = [(doc.name, doc.read_text())]
    if doc.name == "benchmarks.md":
        texts += [(str(p.relative_to(REPO)), p.read_text()) for p in (REPO / "docs" / "benchmarks").rglob("*.json")]
    found = [f"{name}: {m.group(0)}" for name, text in texts for m in MACHINE_FOLDER.finditer(text)]
    assert not found, f"absolute folders of one machine: {found}"
