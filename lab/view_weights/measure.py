"""What the semantic-aware weight net gives the source views that cannot see a surface point (a diagnostic).

S-Ray's semantic ray at a point is s = sum_i w_i F''_i over the views that validly see it (w_i = 0 for the others,
``sray.model.semantic_weights``). A view whose line of sight to the point is blocked by something nearer carries the
occluder's feature, so every share of weight it keeps mixes a wrong class into s. This module reads the weights the
checkpoint's fine field gives at ground-truth surface points of unseen test views (the samples of
:func:`~sray.lab.ceilings.surface_field.surface_passes`, an oracle placement) and sorts each valid view by the
sources' ground-truth depth (``label_transfer.point_hits``, the geometry of its backward test):

* *visible*: the point projects inside the source image, in front of its camera, and its camera depth z agrees
  with the source's depth D there: |z - D| < ``tolerance`` D;
* *occluded*: the same, but the point lies behind the source's surface: z >= (1 + ``tolerance``) D;
* any other valid view (the point in front of the source's surface, or no source depth) is counted in neither.

Per point with n valid views, n w_i is a view's weight relative to the plain mean (1: the mean; tau to 1/tau:
the range ``C(tau)`` allows). On *mixed* points (at least one occluded and one visible valid view) the occluded
views' weight mass sum_occ w_i is compared with the plain mean's, n_occ / n, and with the least ``C(tau)``
permits (:func:`occluded_mass_bounds`); the ranking score is the share of (occluded, visible) view
pairs of a point in which the occluded view weighs less (ties count one half): 0.5 is a blind net, 1 a perfect
one. Accuracy at the surface (the field's argmax there against the query's label) is split the same way: points
some valid view cannot see against points every valid view sees.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import islice
from pathlib import Path
from typing import Any

import torch
from torch import Tensor
from tqdm import tqdm

from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.shards.manifest import read_manifest
from sray.lab.ceilings.surface_field import surface_passes
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel
from sray.platform.eval.label_transfer import point_hits, unproject
from sray.platform.eval.view_scoring import encode_sources
from sray.platform.eval.zero_shot import select_scenes


def ranking_pairs(weights: Tensor, occluded: Tensor, visible: Tensor) -> tuple[Tensor, Tensor]:
    """Per point, the (occluded, visible) view pairs in which the occluded view weighs less (ties one half), and
    the number of such pairs: weights (P, m) float, occluded/visible (P, m) bool -> float64 (P,), int64 (P,)."""
    pair = occluded[:, :, None] & visible[:, None, :]  # (P, m_occ, m_vis)
    w = weights.double()
    lower = (w[:, :, None] < w[:, None, :]).double() + 0.5 * (w[:, :, None] == w[:, None, :]).double()
    return (lower * pair).sum(dim=(1, 2)), pair.sum(dim=(1, 2))


def occluded_mass_bounds(n_occluded: Tensor, n_valid: Tensor, tau: float) -> tuple[Tensor, Tensor]:
    """The occluded views' weight mass under the plain mean, n_occ / n, and the least ``C(tau)`` allows (each
    occluded view above tau / n, each other valid view below 1 / (tau n), all summing to 1):
    max(n_occ tau / n, 1 - (n - n_occ) / (tau n)). Counts (P,) -> float64 (P,), (P,)."""
    n_occ, n = n_occluded.double(), n_valid.double().clamp_min(1.0)
    floor = torch.maximum(n_occ * tau / n, 1.0 - (n - n_occ) / (tau * n))
    return n_occ / n, floor.clamp_min(0.0)


@dataclass
class WeightTally:
    """Running sums over surface points of one checkpoint (module doc); :meth:`summary` reads them out."""

    tau: float
    """The checkpoint's ``model.tau``."""
    points: int = 0
    valid_views: int = 0
    relative_sum: float = 0.0
    relative_squares: float = 0.0
    visible_views: int = 0
    occluded_views: int = 0
    visible_relative: float = 0.0
    occluded_relative: float = 0.0
    pairs: int = 0
    pairs_lower: float = 0.0
    mixed_points: int = 0
    mass: float = 0.0
    mass_plain: float = 0.0
    mass_floor: float = 0.0
    correct_occluded: int = 0
    points_occluded: int = 0
    correct_clear: int = 0
    points_clear: int = 0

    def add(self, weights: Tensor, visible: Tensor, occluded: Tensor, correct: Tensor) -> None:
        """Add surface points: weights (P, m) float (0 for invalid views), visible/occluded (P, m) bool
        (:func:`~sray.platform.eval.label_transfer.point_hits`, transposed), correct (P,) bool (the field's
        argmax is the point's label; only labelled points are given)."""
        valid = weights > 0
        visible, occluded = visible & valid, occluded & valid
        n_valid = valid.sum(1)
        relative = weights.double() * n_valid[:, None].double()  # (P, m) n w_i
        self.points += weights.shape[0]
        self.valid_views += int(n_valid.sum())
        self.relative_sum += float(relative[valid].sum())
        self.relative_squares += float(relative[valid].square().sum())
        self.visible_views += int(visible.sum())
        self.occluded_views += int(occluded.sum())
        self.visible_relative += float(relative[visible].sum())
        self.occluded_relative += float(relative[occluded].sum())
        lower, pairs = ranking_pairs(weights, occluded, visible)
        self.pairs += int(pairs.sum())
        self.pairs_lower += float(lower.sum())
        n_occ, n_vis = occluded.sum(1), visible.sum(1)
        mixed = (n_occ > 0) & (n_vis > 0)
        plain, floor = occluded_mass_bounds(n_occ, n_valid, self.tau)
        self.mixed_points += int(mixed.sum())
        self.mass += float((weights.double() * occluded).sum(1)[mixed].sum())
        self.mass_plain += float(plain[mixed].sum())
        self.mass_floor += float(floor[mixed].sum())
        blocked = n_occ > 0
        self.points_occluded += int(blocked.sum())
        self.correct_occluded += int((correct & blocked).sum())
        self.points_clear += int((~blocked & (n_valid > 0)).sum())
        self.correct_clear += int((correct & ~blocked & (n_valid > 0)).sum())

    def summary(self) -> dict[str, float | int | None]:
        """The JSON-ready figures: the spread (standard deviation) of n w over all valid views, shares of views,
        mean relative weights, ranking score, occluded mass (actual, plain mean, floor) on mixed points and the share
        of the removable mass removed, surface accuracy split by occlusion. None where nothing was counted."""
        def ratio(a: float, b: float) -> float | None:
            return a / b if b else None
        removable = self.mass_plain - self.mass_floor
        mean = ratio(self.relative_sum, self.valid_views)
        spread = None if mean is None else max(self.relative_squares / self.valid_views - mean * mean, 0.0) ** 0.5
        return {"tau": self.tau, "points": self.points, "valid_views": self.valid_views,
                "relative_weight_sd": spread,
                "visible_share": ratio(self.visible_views, self.valid_views),
                "occluded_share": ratio(self.occluded_views, self.valid_views),
                "visible_relative_weight": ratio(self.visible_relative, self.visible_views),
                "occluded_relative_weight": ratio(self.occluded_relative, self.occluded_views),
                "ranking": ratio(self.pairs_lower, self.pairs), "pairs": self.pairs,
                "mixed_points": self.mixed_points, "mixed_share": ratio(self.mixed_points, self.points),
                "occluded_mass": ratio(self.mass, self.mixed_points),
                "occluded_mass_plain": ratio(self.mass_plain, self.mixed_points),
                "occluded_mass_floor": ratio(self.mass_floor, self.mixed_points),
                "removed_share": ratio(self.mass_plain - self.mass, removable) if removable > 0 else None,
                "acc_occluded": ratio(self.correct_occluded, self.points_occluded),
                "acc_clear": ratio(self.correct_clear, self.points_clear)}


def surface_pixels(depth: Tensor, label: Tensor, ignore_id: int, stride: int) -> Tensor:
    """Flat indices (P,) int64 of the pixels of a query view with known depth (H, W) and a label (H, W) other than
    ``ignore_id``, every ``stride``-th pixel in each direction (rows and columns 0, stride, 2 stride, ...)."""
    h, w = depth.shape
    grid = torch.zeros(h, w, dtype=torch.bool)
    grid[::stride, ::stride] = True
    return (grid & (depth > 0) & (label != ignore_id)).reshape(-1).nonzero().squeeze(1)


@torch.no_grad()
def tally_view(tally: WeightTally, net: SRayModel, sample: EvalSample, stride: int, tolerance: float,
               runtime: Runtime = Runtime()) -> None:
    """Add the surface points of one evaluation sample's query view (:func:`surface_pixels`) to ``tally``."""
    encoded = encode_sources(net, sample, torch.device("cpu"))
    src, query, depth, label = sample.sources, sample.query, sample.query_depth, sample.query_label
    pixels = surface_pixels(depth, label, net.cfg.ignore_id, stride)
    points = unproject(depth[None], query.K[None], query.c2w[None])[0]  # (H*W, 3) float64
    flat_label = label.reshape(-1)
    for rays, out, at in surface_passes(net, encoded, query.K, query.c2w, depth, pixels, sample.near, sample.far,
                                        runtime):
        row = torch.arange(rays.numel())
        weights = out["view_weights"][row, :, at]  # (R, m, N) -> (r, m) at the surface sample
        correct = out["logits"][row, at].argmax(-1) == flat_label[rays]  # (r,)
        _, visible, occluded = point_hits(points[rays], src.K, src.c2w, tuple(src.depth.shape[-2:]),
                                          src.depth, tolerance)
        tally.add(weights, visible.T, occluded.T, correct)


def measure_view_weights(net: SRayModel, shards: Path, *, n_source: int = 8, views_per_scene: int = 0, stride: int = 2,
                         tolerance: float = 0.05, runtime: Runtime = Runtime(),
                         progress: bool = True) -> dict[str, Any]:
    """The module doc's figures for ``net`` on the unseen test scenes of ``shards``: the first ``views_per_scene``
    test views of each (0: all) with zero-shot evaluation's fixed ``n_source`` sources, every ``stride``-th
    labelled pixel with known depth in each direction; ``tolerance``: the relative depth agreement of the
    visibility test. Runs on the CPU."""
    if stride < 1:
        raise ValueError(f"stride is {stride}; use 1 (every pixel) or more")
    names, _ = select_scenes(Path(shards), None)
    manifest = read_manifest(Path(shards))
    tally = WeightTally(net.cfg.tau)
    bar = tqdm(desc="view weights", unit="view", disable=not progress)
    for scene in names:
        samples = make_eval_samples(Path(shards), scene, split="test", n_source=n_source, manifest=manifest)
        for sample in islice(samples, views_per_scene or None):
            tally_view(tally, net, sample, stride, tolerance, runtime)
            bar.update(1)
    bar.close()
    return {"shards": str(shards), "scenes": names, "n_source": n_source, "views_per_scene": views_per_scene,
            "stride": stride, "tolerance": tolerance, **tally.summary()}
