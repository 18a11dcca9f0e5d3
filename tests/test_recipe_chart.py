"""CONTRIBUTING.md, "Add a fleet chart", performed: steps used per scene and method, as bars.

The recipe is one entry in ``FLEET_CHARTS`` (``platform/viz/charts.py``; added here for the test's
duration): a function of (results, methods) returning a figure. ``write_fleet_charts`` then writes it
beside the built-in charts, and the bars hold the results' values, in the methods' colours.
"""

from __future__ import annotations

from typing import Any

import cv2
import pytest
from test_charts import mixed_fleet

from sray.platform.finetune.methods.registry import METHODS
from sray.platform.viz import charts
from sray.platform.viz.chart_style import ChartedMethods
from sray.platform.viz.charts import FLEET_CHARTS, write_fleet_charts


def steps_figure(results: list[dict[str, Any]], methods: ChartedMethods) -> Any:
    """Optimisation steps each finished (scene, method) used before it stopped."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    done = [r for r in results if r["status"] == "finished"]
    fig = Figure(figsize=(6, 3), dpi=charts.DPI)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.bar([f"{r['scene']}\n{r['method']}" for r in done], [r["steps_used"] for r in done],
           color=[methods[r["method"]].style.color for r in done])
    ax.set_ylabel("steps used")
    return fig


def test_a_registered_chart_is_written_with_the_fleet(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(FLEET_CHARTS, "steps_used", steps_figure)
    results = mixed_fleet()
    paths = write_fleet_charts(results, tmp_path, METHODS)
    assert tmp_path / "steps_used.png" in paths and len(paths) == len(FLEET_CHARTS)
    image = cv2.imread(str(tmp_path / "steps_used.png"))
    assert image is not None and image.shape[:2] == (3 * charts.DPI, 6 * charts.DPI)
    fig = steps_figure(results, METHODS)
    bars = fig.axes[0].patches
    done = [r for r in results if r["status"] == "finished"]
    assert [b.get_height() for b in bars] == [r["steps_used"] for r in done]
    hex_colour = "#{:02x}{:02x}{:02x}".format(*(round(255 * v) for v in bars[0].get_facecolor()[:3]))
    assert hex_colour == METHODS[done[0]["method"]].style.color
