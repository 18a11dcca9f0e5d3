"""The Pareto chart of ``sray bench speed-accuracy``: mIoU against CPU seconds per view."""

from __future__ import annotations

import textwrap
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png
from sray.jobs.bench.speed_accuracy import pareto
from sray.platform.common.eval_protocol import inputs_name
from sray.platform.finetune.methods.registry import get_method

FAST, FULL = "tab:blue", "tab:gray"  # S-Ray's fast-render and full-render settings


def chart(rows: list[dict], path: Path, protocol: str) -> Path:
    """mIoU (%) against CPU seconds per view (log scale), the front joined by a line, numbered points named in a key
    (nearby names would overlap), another method's row in its zero-shot style, the protocol in the title."""
    fig = Figure(figsize=(11, 6.5))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.07, 0.1, 0.56, 0.74))
    others = {}
    for i, r in enumerate(rows, 1):
        if r["setting"] is None:
            method = get_method(r["method"])
            style = others.setdefault(r["method"], method.zero_shot or method.style)
            ax.scatter(r["s_per_view"], r["miou"], s=60, color=style.color, marker=style.marker)
        else:
            ax.scatter(r["s_per_view"], r["miou"], s=40, color=FAST if r["setting"]["fast"] else FULL)
        ax.annotate(str(i), (r["s_per_view"], r["miou"]), textcoords="offset points", xytext=(4, 3), fontsize=8)
    front = pareto(rows)
    ax.plot([r["s_per_view"] for r in front], [r["miou"] for r in front], color="tab:orange", lw=1.5,
            label="Pareto front")
    ax.scatter([], [], color=FAST, label="S-Ray, fast render mode")
    ax.scatter([], [], color=FULL, label="S-Ray, full render")
    for style in others.values():
        ax.scatter([], [], color=style.color, marker=style.marker, label=style.label)
    ax.set_xscale("log")
    ax.set_xlabel("CPU seconds per view (log scale; this process, all threads)")
    ax.set_ylabel("mIoU (%)")
    ax.grid(True, which="both", alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), loc="lower left", bbox_to_anchor=(0.655, 0.1), fontsize=8)
    key = [f"{i:>2}  {r['name']} ({inputs_name(r['inputs'])}): {r['miou']:.2f}%, {r['s_per_view']:.2f} CPU s"
           for i, r in enumerate(rows, 1)]
    fig.text(0.66, 0.84, "\n".join(key), va="top", ha="left", family="monospace", fontsize=8)
    what = "S-Ray's render settings" + (f" and {', '.join(others)}" if others else "")
    title = [f"Zero-shot accuracy against render time: {what}"] + textwrap.wrap(protocol, 150)
    fig.text(0.5, 0.98, "\n".join(title), va="top", ha="center", fontsize=8)
    return save_png(fig, path, dpi=120)
