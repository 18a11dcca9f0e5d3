"""Watching what a point renders: rays whose outputs are not finite are counted (a point with any is ``failed``), and
the fault drill ``stability.nan_points`` poisons a point's renders with NaN (``sray.platform.common.fault_hook``)."""

from __future__ import annotations

import torch
from torch import Tensor

from sray.model.view_render import RayRenderer


class OutputWatch:
    """Wraps renderers: counts rays whose fine outputs are not finite, and can poison them (a fault drill).

    A ray with no prediction (every logit -inf: ``2d-transfer`` where no source sees the pixel) is a miss, not a
    non-finite output: only NaN and +inf count."""

    def __init__(self, poison: bool) -> None:
        """``poison``: replace every rendered logit with NaN."""
        self.nonfinite_rays, self.poison = 0, poison

    def wrap(self, render: RayRenderer) -> RayRenderer:
        """The renderer, watched."""

        def watched(o: Tensor, d: Tensor, near: Tensor, far: Tensor) -> dict[str, dict[str, Tensor]]:
            out = render(o, d, near, far)
            fine = out["fine"]
            if self.poison:
                fine = {**fine, "logits": torch.full_like(fine["logits"], float("nan"))}
                out = {**out, "fine": fine}
            logits, rgb = fine["logits"], fine["rgb"]                                       # (R, L), (R, 3)
            bad = (torch.isnan(logits) | torch.isposinf(logits)).any(-1) | ~torch.isfinite(rgb).all(-1)  # (R,)
            self.nonfinite_rays += int(bad.sum())
            return out

        return watched
