"""How charts draw a method: its :class:`ChartStyle`, and what a chart needs to know of a method.

Charts sit below the method registry (``platform/finetune/methods``), so they never import it: the
caller hands them a mapping of method name -> an object with ``name``, ``style`` and ``zero_shot``
(a registered ``Method`` is one), in chart and legend order.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True)
class ChartStyle:
    """How charts draw one kind of curve."""

    label: str
    """Legend text."""
    color: str
    """Matplotlib colour (``#rrggbb``)."""
    marker: str
    """Matplotlib marker of its evaluated points."""


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
