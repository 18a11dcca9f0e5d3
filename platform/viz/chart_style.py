"""How charts draw a method (:class:`ChartStyle`) and what they read of one (:class:`ChartedMethod`); charts sit
below the method registry, so callers hand them the methods (a registered ``Method`` is one)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True)
class ChartStyle:
    """How charts draw one kind of curve: legend text, matplotlib colour (``#rrggbb``), marker of its points."""

    label: str
    color: str
    marker: str


class ChartedMethod(Protocol):
    """What a chart reads of a method."""

    @property
    def name(self) -> str:
        """The method's name (a result's ``method`` field)."""

    @property
    def style(self) -> ChartStyle:
        """How its curves and points are drawn."""

    @property
    def zero_shot(self) -> ChartStyle | None:
        """Set when its step-0 score is a zero-shot model, drawn as its own line."""


ChartedMethods = Mapping[str, ChartedMethod]
"""Method name -> what charts read of it, in chart and legend order."""
