"""Every published number from stored results, in one pass: the generated blocks of README.md and docs/**/*.md
(:mod:`sray.lab.publish.blocks`, renderers in :mod:`sray.lab.publish.figures`), the benchmarks' pages
(:mod:`sray.lab.publish.pages`) and the studies' pages (:mod:`sray.lab.publish.study_pages`). :func:`published` says
what each file should hold; :func:`publish` writes the files that differ (atomically) or, checking, only lists them."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from sray.data_tools.atomic import atomic_write_text
from sray.lab.publish.blocks import BlockError, blocks, fill
from sray.lab.publish.figures import RENDERERS
from sray.lab.publish.pages import render_page, slugs
from sray.lab.publish.study_pages import expected_page, specs


def documents(repo: Path) -> list[Path]:
    """The README and every Markdown file under docs/ (sub-folders included)."""
    return [Path(repo) / "README.md", *sorted((Path(repo) / "docs").rglob("*.md"))]


def _render(repo: Path, where: str) -> Callable[[str], str]:
    def render(name: str) -> str:
        if name not in RENDERERS:
            raise BlockError(f"{where}: no renderer named {name!r}; known: {', '.join(RENDERERS)}")
        return RENDERERS[name](Path(repo))
    return render


def published(repo: Path) -> dict[Path, str]:
    """Each generated file's expected text: the benchmarks' and the studies' pages, then every document holding a
    generated block."""
    repo = Path(repo)
    docs = repo / "docs"
    expected = {docs / "benchmarks" / f"{slug}.md": render_page(docs, slug) for slug in slugs(docs)}
    expected.update(expected_page(spec, docs) for spec in specs(repo))
    for path in documents(repo):
        text = expected.get(path, path.read_text() if path.exists() else "")
        where = str(path.relative_to(repo))
        if blocks(text, where):
            expected[path] = fill(text, _render(repo, where), where)
    return expected


def publish(repo: Path, check: bool = False) -> list[Path]:
    """Bring every generated file up to date with the stored results (``check``: change nothing); returns the files
    that were (or, checking, would be) rewritten."""
    expected = published(repo)
    stale = [path for path, text in expected.items() if not path.exists() or path.read_text() != text]
    if not check:
        for path in stale:
            atomic_write_text(path, expected[path])
    return stale
