"""Source views of a fly-through frame: zero-shot evaluation's rule, applied to cameras no shard has ranked.

``sray eval`` gives each test view its top-ranked ``n_source`` neighbours inside the scene's ``source``
split, ranked when the shards were written (``data_tools/shards/neighbours.py``, rule ``frustum-overlap``).
A test view is ranked "blind" there: by how much of each candidate's own back-projected grid points lands
in front of and inside the query camera, which needs only the query's pose and intrinsics. A fly-through
frame is such a camera, so it is ranked by the same score and tie-breaks at render time
(``neighbours.rank_camera``, which ``rank_neighbours`` shares them with).

Candidates: the ``source`` split of a test scene; the ``train`` split minus the held-out ``test`` views of
a train scene (``scene.source_pool``), as in evaluation. Depth is read only from the views of
``scene.source_pool`` (the candidates' grid points and the fallback depth for a view without enough
depth), so no ``test`` view's pixels, depth or labels are ever decoded.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from sray.data_tools.loader.sample_types import SourceViews
from sray.data_tools.loader.views import StoredView
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.neighbours import fallback_depth, grid_points, grid_samples, rank_camera


def candidate_views(meta: SceneMeta) -> list[str]:
    """View ids a frame's sources are chosen from, in capture order (module doc); ValueError when none."""
    if meta.role != "test":
        return source_pool(meta)
    allowed = set(meta.splits.get("source", []))
    ids = [v for v in meta.view_ids if v in allowed]
    if not ids:
        raise ValueError(f"scene {meta.name!r}: field 'splits' has no 'source' views to render from")
    return ids


class SourcePicker:
    """Ranks a scene's candidate source views for any camera and assembles the chosen ones."""

    def __init__(self, views: dict[str, StoredView], meta: SceneMeta, n_source: int) -> None:
        """``views``: the scene's stored views by id (``read_scene_views``); ``n_source``: sources per frame."""
        self.views, self.n_source = views, n_source
        self.candidates = candidate_views(meta)
        if not 1 <= n_source <= len(self.candidates):
            raise ValueError(f"scene {meta.name!r}: n_source is {n_source}, but it has {len(self.candidates)} "
                             "candidate source views; pass --n-source between 1 and that")
        samples = {v: grid_samples(views[v].depth()) for v in source_pool(meta)}
        fallback = fallback_depth(list(samples.values()), (meta.near, meta.far))
        self.points = {v: grid_points(samples[v], views[v].K, views[v].c2w, fallback) for v in self.candidates}
        self.c2ws = np.stack([views[v].c2w for v in self.candidates])                    # (C, 4, 4)
        self._decoded: dict[str, tuple[Tensor, Tensor]] = {}

    def choose(self, K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int]) -> list[str]:
        """The ``n_source`` best candidates, best first, for a camera K (3, 3), c2w (4, 4) of size ``hw``
        (``neighbours.rank_camera``: the shards' ranking of a test view, tie-breaks included)."""
        order, _ = rank_camera(np.asarray(K, np.float64), np.asarray(c2w, np.float64), hw, self.c2ws,
                               [self.points[v] for v in self.candidates], self.n_source)
        return [self.candidates[i] for i in order]

    def sources(self, ids: list[str]) -> SourceViews:
        """The views ``ids`` as model inputs: rgb (m, 3, H, W) in [0, 1], K (m, 3, 3), c2w (m, 4, 4), depth
        (m, H, W) in metres; each view is decoded once and kept."""
        for v in ids:
            if v not in self._decoded:
                rgb = torch.from_numpy(self.views[v].rgb()).permute(2, 0, 1).float().div_(255.0)  # (3, H, W)
                self._decoded[v] = rgb, torch.from_numpy(self.views[v].depth())                 # (H, W)
        return SourceViews(rgb=torch.stack([self._decoded[v][0] for v in ids]),
                           K=torch.from_numpy(np.stack([self.views[v].K for v in ids])).float(),
                           c2w=torch.from_numpy(np.stack([self.views[v].c2w for v in ids])).float(),
                           depth=torch.stack([self._decoded[v][1] for v in ids]))
