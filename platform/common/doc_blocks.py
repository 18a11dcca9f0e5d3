"""Markdown pipe tables as data and back, and absolute paths rewritten repository-relative or as ``OUT/…``."""

from __future__ import annotations

import os
import re
from pathlib import Path

_RULE = re.compile(r"^\|?\s*:?-{3,}:?\s*(\|\s*:?-{3,}:?\s*)*\|?\s*$")
_CELL_SPLIT = re.compile(r"(?<!\\)\|")


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    """A Markdown table: the header, its rule, one line per row (cells converted with ``str``, ``|`` escaped)."""
    def cells(values: list) -> str:
        return " | ".join(str(c).replace("|", "\\|") for c in values)

    return "\n".join([cells(header), " | ".join("---" for _ in header)] + [cells(r) for r in rows])


def _cells(line: str) -> list[str]:
    """The stripped cells of one table line (outer pipes optional, ``\\|`` kept as an escaped pipe)."""
    line = line.strip()
    line = line[1:] if line.startswith("|") else line
    line = line[:-1] if line.endswith("|") and not line.endswith("\\|") else line
    return [c.strip() for c in _CELL_SPLIT.split(line)]


def parse_blocks(markdown: str) -> list[dict]:
    """``markdown`` as blocks: ``{"header", "align", "rows", "outer_pipes"}`` per pipe table, ``{"text"}`` between."""
    lines = markdown.strip("\n").splitlines()
    blocks: list[dict] = []
    text: list[str] = []

    def flush_text() -> None:
        joined = "\n".join(text).strip("\n")
        if joined.strip():
            blocks.append({"text": joined})
        text.clear()

    i = 0
    while i < len(lines):
        if "|" in lines[i] and i + 1 < len(lines) and _RULE.match(lines[i + 1].strip()):
            flush_text()
            header, align = _cells(lines[i]), _cells(lines[i + 1])
            rows, i = [], i + 2
            while i < len(lines) and "|" in lines[i] and lines[i].strip():
                rows.append(_cells(lines[i]))
                i += 1
            blocks.append({"header": header, "align": align, "rows": rows,
                           "outer_pipes": lines[i - len(rows) - 2].strip().startswith("|")})
        else:
            text.append(lines[i])
            i += 1
    flush_text()
    return blocks


def render_blocks(blocks: list[dict]) -> str:
    """The Markdown of ``blocks`` (``parse_blocks``' inverse up to whitespace), blocks separated by a blank line."""
    parts = []
    for block in blocks:
        if "text" in block:
            parts.append(block["text"])
            continue
        lines = [block["header"], block["align"], *block["rows"]]
        edge = "|" if block.get("outer_pipes", True) else ""
        parts.append("\n".join(f"{edge} {' | '.join(cells)} {edge}".strip() if edge else " | ".join(cells)
                               for cells in lines))
    return "\n\n".join(parts)


_LINK = re.compile(r"(\]\()([^)\s#:]+)(\))")


def rebase_links(markdown: str, from_dir: Path, to_dir: Path) -> str:
    """``markdown`` with each relative link target (``](path)``) rewritten from ``from_dir`` to ``to_dir``."""
    if os.path.abspath(from_dir) == os.path.abspath(to_dir):
        return markdown
    return _LINK.sub(lambda m: m.group(1) + os.path.relpath(os.path.join(from_dir, m.group(2)), to_dir) + m.group(3),
                     markdown)


_ABSOLUTE = re.compile(r"(?:(?<=^)|(?<=[\s`'\"(=,])|(?<=:///))(/[\w.@+~-]+(?:/[\w.@+~-]*)+)")
"""An absolute file path at a word start, after ``=`` or inside ``sqlite:///``."""


def portable(texts: list[str], root: Path) -> list[str]:
    """``texts`` with absolute paths relative to ``root``, or ``OUT/`` + the path below the others' common folder."""
    root = Path(os.path.abspath(root))
    found = {m.group(1).rstrip(".") for t in texts for m in _ABSOLUTE.finditer(t)}
    outside = {p for p in found if not _under(p, root)}
    base = os.path.commonpath([os.path.dirname(p) for p in outside]) if outside else "/"

    def rewrite(match: re.Match) -> str:
        path = match.group(1)
        cut = len(path) - len(path.rstrip("."))
        path, tail = (path[:-cut], path[-cut:]) if cut else (path, "")
        if _under(path, root):
            return (os.path.relpath(path, root) if path.rstrip("/") != str(root) else ".") + tail
        return "OUT/" + os.path.relpath(path, base) + tail

    return [_ABSOLUTE.sub(rewrite, t) for t in texts]


def _under(path: str, root: Path) -> bool:
    """Whether ``path`` lies inside ``root`` (or is it)."""
    return Path(os.path.abspath(path)).is_relative_to(root)
