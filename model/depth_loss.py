"""The optional training-time depth term (``SRayConfig.lambda_depth``; a departure from the paper, docs/model.md).

Per render pass, over the rays whose ground-truth depth is known (> 0; 0 = unknown in every scene format):

    L_depth = sum_r known_r |D_r - D*_r| / (far_r - near_r)  /  max(sum_r known_r, 1)

- ``D`` is the pass's ``depth`` output, ``sum_k w_k z_k`` (``rendering.composite``): the expected ray parameter,
  which for ``pixel_rays`` directions (camera-z 1) is the camera **z-depth**, the quantity the shards store. Like
  is compared with like; no conversion to distance along the ray. It is not divided by the opacity: the empty
  remainder of a ray counts as depth 0, so on a ray that hits a surface (every ray with a depth reading does)
  the term also asks for full opacity there instead of dividing by a near-zero opacity.
- **L1**, not smooth-L1 or L2: ground-truth depth has outliers the loss should not chase, mixed pixels at
  occlusion edges (a depth from one surface where colour and label blend two) and sensor noise; L1's gradient
  keeps its size whatever the error, and it needs no threshold (smooth-L1's beta) that nothing measured here
  could set.
- **Scale-free** by the ray's depth range ``far - near`` (the scene's own bounds): the range the samples cover
  and the unit of the normalised depth (z - near) / (far - near) the network already encodes, so an error of
  the whole sampled range costs 1 in a 3 m room and in a 10 m hall alike and the weight transfers across
  datasets.
- A batch without a known depth gives exactly 0 with a zero gradient; no boolean indexing (no device sync).
"""

from __future__ import annotations

from dataclasses import dataclass

from torch import Tensor


@dataclass(frozen=True)
class DepthTarget:
    """The ground truth of the depth term for R rays."""

    depth: Tensor
    """float32 (R,) ground-truth z-depth of each ray's query pixel in metres, 0 = unknown."""
    span: Tensor
    """float32 (R,) the ray's depth range far - near (> 0), the unit of the error."""

    def __post_init__(self) -> None:
        """ValueError unless both are (R,) tensors of one length."""
        if self.depth.ndim != 1 or self.span.shape != self.depth.shape:
            raise ValueError(f"sray.model.depth_loss.DepthTarget: depth and span must both be (R,), got "
                             f"{tuple(self.depth.shape)} and {tuple(self.span.shape)}; pass the query pixels' "
                             "depth and far - near per ray.")

    @classmethod
    def of_rays(cls, depth: Tensor, near: Tensor, far: Tensor) -> DepthTarget:
        """The target of rays with ground-truth z-depth ``depth`` (R,) and bounds ``near``, ``far`` (R,)."""
        return cls(depth=depth.float(), span=(far - near).float())

    def known(self) -> Tensor:
        """(R,) float32: 1 where the ground-truth depth is known (> 0), else 0."""
        return (self.depth > 0).float()

    def __getitem__(self, rays: slice) -> DepthTarget:
        """The target of a slice of the rays (a piece of a batch)."""
        return DepthTarget(depth=self.depth[rays], span=self.span[rays])


def depth_l1(depth: Tensor, target: DepthTarget) -> Tensor:
    """Mean over the rays of known ground truth of |depth - target| / span (the module docstring's L_depth):
    depth (R,) a pass's rendered z-depth. Computed in float32; exactly 0 with a zero gradient when no ray's depth
    is known."""
    known = target.known()  # (R,)
    error = (depth.float() - target.depth).abs() / target.span.clamp_min(1e-6)  # (R,)
    return (error * known).sum() / known.sum().clamp_min(1.0)
