"""Source views of a fly-through frame, ranked as for a held-out test view (``neighbours.rank_camera``: pose and
intrinsics only) among a test scene's ``source`` split or a train scene's pool; no ``test`` view is ever decoded."""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from sray.data_tools.loader.sample_types import SourceViews
from sray.data_tools.loader.views import StoredView
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.neighbours import fallback_depth, grid_points, grid_samples, rank_camera


class SourcePicker:
    """Ranks a scene's candidate source views for any camera and assembles the chosen ones."""

    def __init__(self, views: dict[str, StoredView], meta: SceneMeta, n_source: int) -> None:
        """``views``: the scene's stored views by id (``read_scene_views``); ``n_source``: sources per frame."""
        self.views, self.n_source = views, n_source
        allowed = set(meta.splits.get("source", []))
        self.candidates = [v for v in meta.view_ids if v in allowed] if meta.role == "test" else source_pool(meta)
        if meta.role == "test" and not self.candidates:
            raise ValueError(f"scene {meta.name!r}: field 'splits' has no 'source' views to render from")
        if not 1 <= n_source <= len(self.candidates):
            raise ValueError(f"scene {meta.name!r}: n_source is {n_source}, but it has {len(self.candidates)} "
                             "candidate source views; pass --n-source between 1 and that")
        samples = {v: grid_samples(views[v].depth()) for v in source_pool(meta)}
        fallback = fallback_depth(list(samples.values()), (meta.near, meta.far))
        self.points = [grid_points(samples[v], views[v].K, views[v].c2w, fallback) for v in self.candidates]
        self.c2ws = np.stack([views[v].c2w for v in self.candidates])                    # (C, 4, 4)
        self._decoded: dict[str, tuple[Tensor, Tensor]] = {}

    def choose(self, K: np.ndarray, c2w: np.ndarray, hw: tuple[int, int]) -> list[str]:
        """The ``n_source`` best candidates, best first, for a camera K (3, 3), c2w (4, 4) of size ``hw``."""
        order, _ = rank_camera(np.asarray(K, np.float64), np.asarray(c2w, np.float64), hw, self.c2ws, self.points,
                               self.n_source)
        return [self.candidates[i] for i in order]

    def sources(self, ids: list[str]) -> SourceViews:
        """Views ``ids`` as model inputs, each decoded once: rgb (m, 3, H, W) in [0, 1], K, c2w, depth (m, H, W) m."""
        for v in ids:
            if v not in self._decoded:
                rgb = torch.from_numpy(self.views[v].rgb()).permute(2, 0, 1).float().div_(255.0)  # (3, H, W)
                self._decoded[v] = rgb, torch.from_numpy(self.views[v].depth())                 # (H, W)
        return SourceViews(rgb=torch.stack([self._decoded[v][0] for v in ids]),
                           K=torch.from_numpy(np.stack([self.views[v].K for v in ids])).float(),
                           c2w=torch.from_numpy(np.stack([self.views[v].c2w for v in ids])).float(),
                           depth=torch.stack([self._decoded[v][1] for v in ids]))
