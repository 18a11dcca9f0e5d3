"""Generated blocks of a Markdown file: the lines between ``<!-- published: NAME -->`` and
``<!-- /published: NAME -->`` are written by ``python -m sray.lab.publish`` from stored results (the renderer NAME
names them); everything outside the blocks is the author's and is kept byte for byte."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

_START = re.compile(r"^<!-- published: ([\w-]+) -->$", re.M)


def start_line(name: str) -> str:
    """The line that opens block ``name``."""
    return f"<!-- published: {name} -->"


def end_line(name: str) -> str:
    """The line that closes block ``name``."""
    return f"<!-- /published: {name} -->"


@dataclass(frozen=True)
class Block:
    """One generated block of a file: its renderer's name and the text between its two marker lines."""

    name: str
    body: str


class BlockError(ValueError):
    """A file's markers do not pair up (the message names the file, the block and the fix)."""


def blocks(text: str, where: str) -> list[Block]:
    """The generated blocks of ``text`` in order; BlockError when a block is not closed, or closed twice."""
    found = []
    for match in _START.finditer(text):
        name = match.group(1)
        end = text.find("\n" + end_line(name), match.end())
        if end < 0:
            raise BlockError(f"{where}: block {name!r} opened by {start_line(name)} has no {end_line(name)}; add it")
        found.append(Block(name, text[match.end():end].strip("\n")))
    for name in set(b.name for b in found):
        if text.count(end_line(name)) != text.count(start_line(name)):
            raise BlockError(f"{where}: block {name!r} has unpaired markers; keep one {end_line(name)} per opening")
    return found


def fill(text: str, render: Callable[[str], str], where: str) -> str:
    """``text`` with every block's body replaced by ``render(name)`` (stripped), the rest unchanged."""
    out, pos = [], 0
    blocks(text, where)  # markers checked before anything is rewritten
    for match in _START.finditer(text):
        name = match.group(1)
        end = text.find("\n" + end_line(name), match.end())
        out += [text[pos:match.end()], "\n", render(name).strip("\n")]
        pos = end
    return "".join(out) + text[pos:]
