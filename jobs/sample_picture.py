"""A picture of one training sample from the streaming loader (the demo shows what the model sees)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from sray.data_tools.atomic import save_png
from sray.data_tools.loader.sample_types import TrainSample
from sray.platform.viz.palette import palette


def write_sample_picture(sample: TrainSample, class_names: list[str], path: Path, ignore_id: int = 255) -> Path:
    """Query view with its sampled ray pixels, the ray targets' labels, and the m source views.

    The query image itself is not in a training sample, so the panel shows the sampled pixels'
    colours and labels scattered at their positions over the query frame, next to the source views.
    """
    src = sample.sources.rgb.permute(0, 2, 3, 1).numpy()  # (m, H, W, 3)
    m, h, w = src.shape[:3]
    uv = sample.pixels.numpy()  # (R, 2)
    labels = sample.target_label.numpy()  # (R,)
    colours = sample.target_rgb.numpy()  # (R, 3)
    pal = palette(len(class_names)) / 255.0
    label_colours = np.where((labels == ignore_id)[:, None], 0.0, pal[np.minimum(labels, len(class_names) - 1)])

    cols = max(m, 2)
    fig = Figure(figsize=(3 * cols, 5.2))
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, cols, squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, colour, title in ((axes[0, 0], colours, "query: sampled ray colours"),
                              (axes[0, 1], label_colours, "query: sampled ray labels")):
        ax.set_facecolor("0.85")
        ax.axis("on")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.scatter(uv[:, 0], uv[:, 1], c=colour, s=6)
        ax.set_xlim(-0.5, w - 0.5)
        ax.set_ylim(h - 0.5, -0.5)
        ax.set_title(title, fontsize=9)
    present = sorted(int(c) for c in np.unique(labels) if c != ignore_id)
    handles = [Line2D([], [], marker="s", ls="", color=pal[c], label=class_names[c]) for c in present]
    if (labels == ignore_id).any():
        handles.append(Line2D([], [], marker="s", ls="", color="black", label=f"ignore ({ignore_id})"))
    axes[0, 2 if cols > 2 else 1].legend(handles=handles, loc="center", fontsize=7, frameon=False, ncol=2)
    for i in range(m):
        axes[1, i].imshow(src[i])
        axes[1, i].set_title(f"source {i + 1}", fontsize=9)
    fig.suptitle(f"scene {sample.scene}, query view {sample.query_id}: {len(uv)} rays, "
                 f"{m} source views, depth range {sample.near:.2f}-{sample.far:.2f} m", fontsize=10)
    fig.tight_layout()
    save_png(fig, path, 100)
    return path
