"""The one render-and-score loop of every held-out score: each sample rendered by ``predict_view`` (under the
caller's autocast), then the scene's views scored together in float32 with autocast off (``score_views``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import torch

from sray.data_tools.loader.sample_types import EvalSample
from sray.model.fast_render import FastRender
from sray.model.view_render import RayRenderer
from sray.platform.eval.view_scoring import ViewPrediction, predict_view, score_views


@dataclass(frozen=True)
class ScoredScene:
    """A scene's rendered held-out views and their scores."""

    scores: dict[str, float]
    """``score_views``'s."""
    views: list[ViewPrediction]
    """In the order of the samples."""


def score_scene(renderer: Callable[[EvalSample], RayRenderer], samples: Iterable[EvalSample], n_classes: int,
                ignore_id: int, stride: int, chunk: int, device: torch.device, fast: FastRender | None = None,
                on_view: Callable[[ViewPrediction], None] | None = None) -> ScoredScene:
    """Render every sample of one scene with ``renderer(sample)`` (``predict_view``'s ``stride``, ``chunk`` and
    ``fast``) and score them; ``on_view`` gets each view once rendered. ValueError when there is no sample."""
    views = []
    for sample in samples:
        views.append(predict_view(renderer(sample), sample, stride, chunk, device, fast))
        if on_view is not None:
            on_view(views[-1])
    if not views:
        raise ValueError("sray.platform.eval.scene_scoring: no evaluation sample to score; the scene needs at "
                         "least one held-out (test) view")
    with torch.autocast("cpu", enabled=False):
        return ScoredScene(score_views(views, n_classes, ignore_id), views)
