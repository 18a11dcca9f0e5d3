"""Measured figures in prose: the patterns ``tests/test_published_numbers.py`` looks for outside generated blocks,
and the text of a Markdown file that lies outside them."""

from __future__ import annotations

import ast
import re

MEASURED = [
    re.compile(r"\d+\.\d+\s?%"),                                   # a decimal percentage: 53.94%
    re.compile(r"\d\s?±|±\s?\d"),                                    # a spread over seeds (not the word "mean ± sd")
    re.compile(r"\d[\d,.]*\s?(?:rays|views|samples|steps|it)/s\b"),  # a throughput
    re.compile(r"\bs\s?/\s?view\b|\bs per (?:rendered )?view\b|CPU s per\b"),  # a time per view or step
    re.compile(r"\d+(?:\.\d+)?\s?(?:GiB|MiB|GB|MB)\b"),             # a memory footprint
    re.compile(r"\d+(?:\.\d+)?\s?(?:min|minutes|hours?)\b"),         # a duration
    re.compile(r"\d+\.\d+\s?(?:ms|s|CPU s)\b|\d+\s?ms\b"),              # a measured time (budgets are integers)
    re.compile(r"\d\.\d+x\b"),                                       # a measured ratio: 1.55x
]
"""What a measured figure looks like in prose (a percentage of accuracy is caught by the next pattern too)."""
SCORE_WORDS = re.compile(r"mIoU|IoU|accuracy|zero-shot|held-out|clean|scores?\b|lost|loses|keeps", re.I)
WHOLE_PERCENT = re.compile(r"(?<![\d.,])\d+\s?%")
"""An integer percentage counts as measured on a line that speaks of a score."""


def generated_spans(text: str) -> list[tuple[int, int]]:
    """Character spans of the generated blocks: ``<!-- published: NAME -->`` to its closing line."""
    spans = []
    for match in re.finditer(r"^<!-- published: ([\w-]+) -->$", text, re.M):
        end = text.find(f"<!-- /published: {match.group(1)} -->", match.end())
        spans.append((match.start(), len(text) if end < 0 else end))
    return spans


def hand_written_lines(text: str, generated_page: bool = False) -> list[tuple[int, str]]:
    """(line number, line) of ``text`` written by hand: outside generated blocks; on a ``generated_page`` (a
    benchmark's page, ``docs/benchmarks/<name>.md``) only its ``## Reading`` section."""
    if generated_page:
        start = text.find("\n## Reading\n")
        spans = [(0, len(text))] if start < 0 else [(0, start)]
    else:
        spans = generated_spans(text)
    lines, offset = [], 0
    for number, line in enumerate(text.splitlines(keepends=True), 1):
        if not any(a <= offset < b for a, b in spans):
            lines.append((number, line.rstrip("\n")))
        offset += len(line)
    return lines


def measured_figures(line: str) -> list[str]:
    """The measured figures one line of prose holds."""
    found = [m.group(0) for pattern in MEASURED for m in pattern.finditer(line)]
    if SCORE_WORDS.search(line):
        found += [m.group(0) for m in WHOLE_PERCENT.finditer(line)]
    return found


def docstring_figures(source: str) -> list[tuple[int, str]]:
    """(line of the docstring, figure) of every measured figure in the docstrings of a Python module's ``source``
    (module, class, function and attribute docstrings: every string that stands as a statement of its own)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            found += [(node.lineno, f) for line in node.value.value.splitlines() for f in measured_figures(line)]
    return found
