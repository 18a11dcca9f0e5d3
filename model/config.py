"""Configuration of the S-Ray network (``SRayModel``): one typed dataclass, validated on creation."""

from __future__ import annotations

from dataclasses import dataclass

from .attention_variants import ATTENTION_VARIANTS
from .semantic_cues import check_cues

FINE_SAMPLES = ("union", "new")
"""What the fine pass evaluates: ``new`` only the n_fine resampled depths (the paper's public code); ``union``
the sorted union with the coarse depths (NeRF). ``new`` trained better and faster (docs/performance.md)."""

INPUTS = ("rgb", "rgbd")
"""What the network is given of its source views: ``rgb`` posed colour images only (the paper); ``rgbd`` also
their depth maps, which place the coarse samples (``depth_sampling``). The query's depth is never an input."""


@dataclass
class SRayConfig:
    """Every setting of the S-Ray network, its sampling and its loss weights: what a checkpoint stores (how it is
    run is ``runtime.Runtime``). Defaults are the paper's (Method section, appendix tables) where it states one."""

    n_classes: int = 20
    """Number of semantic classes L the classifier predicts (ScanNet benchmark: 20)."""
    feat_dim: int = 32
    """Channels C of the image features and of the contextual space M (paper: 32)."""
    encoder_width: int = 16
    """Channels of the image encoder's first layer, every later layer scaled with it (16 = the appendix table)."""
    n_source: int = 8
    """Source views m a training sample carries (paper: 8); the network accepts any m >= 1."""
    n_coarse: int = 64
    """Coarse samples per ray, stratified in training and bin centres in evaluation (paper: 64)."""
    n_fine: int = 64
    """Fine samples per ray drawn from the coarse weights (paper code: 64); evaluated as ``fine_samples`` says."""
    attention: str = "full"
    """Cross-Reprojection Attention variant, a key of ``attention_variants.ATTENTION_VARIANTS`` (``full`` = the
    paper's CRA, ``intra``, ``cross``, ``none``, ``dense``)."""
    n_heads: int = 4
    """Heads of every multi-head attention (CRA and the geometry net's ray attention; paper: 4)."""
    depth_freqs: int = 6
    """Frequencies of the encoding of each sample's normalised depth (z - near) / (far - near) whose learned
    projection is added to M before intra-view attention (0 = the raw depth only)."""
    dir_hidden: int = 16
    """Hidden width of the view-direction MLP (4 -> 16 -> C, appendix L21)."""
    weight_hidden: tuple[int, int] = (16, 8)
    """Hidden widths of the semantic-aware weight net (37 -> 16 -> 8 -> 1, appendix)."""
    geo_hidden: tuple[int, int] = (32, 16)
    """Widths of the geometry net's MLP on [mean, variance] (64 -> 32 -> 16, appendix L8)."""
    tau: float = 0.7
    """Bound of the semantic-aware weights: tau/m < w_i < 1/(tau m); tau = 1 is the plain mean."""
    min_source_depth: float = 1e-3
    """A projection is valid only at least this far (camera z, scene units) in front of the source camera."""
    lambda_sem: float = 1.0
    """Weight of the semantic cross-entropy in the training loss (paper: 1)."""
    lambda_rgb: float = 1.0
    """Weight of the photometric MSE in the training loss (paper: 1)."""
    lambda_src_sem: float = 0.0
    """Weight of the auxiliary per-pixel cross-entropy of a linear head on the encoder's feature maps against the source
    views' labels (``source_semantics``, docs/model.md; 0: the paper, no head). The head exists only in training."""
    ignore_id: int = 255
    """Label id of unlabelled pixels; never a prediction target."""
    class_weights: tuple[float, ...] = ()
    """Per-class weights of the semantic cross-entropy (n_classes of them; empty = unweighted, the paper's loss),
    filled from the class frequencies when ``data.class_balance`` asks (``loader.class_stats.balanced_weights``)."""
    fine_samples: str = "new"
    """Depths the fine pass evaluates, one of ``FINE_SAMPLES``."""
    inputs: str = "rgb"
    """Source-view inputs, one of ``INPUTS`` (same parameters: a checkpoint of either mode loads in the other)."""
    depth_fraction: float = 0.5
    """``rgbd`` only: share of the coarse samples in the band around the surface the source depths show on the ray;
    the rest cover [near, far] uniformly, so nothing is lost where the sources are wrong."""
    depth_band: float = 0.1
    """``rgbd`` only: half-width of that band in z-depth (scene units, metres), clipped to [near, far]."""
    semantic_cues: tuple[str, ...] = ()
    """Appearance-free inputs of the semantic head besides the semantic ray, names from ``semantic_cues.CUES``;
    empty is the paper's head. A departure from the paper (docs/model.md): the classifier's first layer widens."""

    def __post_init__(self) -> None:
        """Reject settings the network cannot run with, naming the field and the fix."""

        def bad(field: str, why: str) -> ValueError:
            return ValueError(f"sray.model.config.SRayConfig: field `{field}` {why}.")

        try:
            check_cues(tuple(self.semantic_cues))
        except ValueError as e:
            raise bad("semantic_cues", f"is {self.semantic_cues!r}; {e}") from None
        if self.attention not in ATTENTION_VARIANTS:
            raise bad("attention", f"is {self.attention!r}; use one of {tuple(ATTENTION_VARIANTS)}")
        if self.fine_samples not in FINE_SAMPLES:
            raise bad("fine_samples", f"is {self.fine_samples!r}; use one of {FINE_SAMPLES}")
        if self.inputs not in INPUTS:
            raise bad("inputs", f"is {self.inputs!r}; use one of {INPUTS}")
        if not 0.0 <= self.depth_fraction <= 1.0:
            raise bad("depth_fraction", f"is {self.depth_fraction}; it must lie in [0, 1]")
        if self.depth_band <= 0.0:
            raise bad("depth_band", f"is {self.depth_band}; it must be > 0 (metres)")
        if self.lambda_src_sem < 0:
            raise bad("lambda_src_sem", f"is {self.lambda_src_sem}; use 0 (no source-view head) or a positive weight")
        if self.depth_freqs < 0:
            raise bad("depth_freqs", f"is {self.depth_freqs}; use 0 or more")
        for name in ("n_classes", "feat_dim", "encoder_width", "n_source", "n_coarse", "n_fine", "n_heads",
                     "dir_hidden"):
            if int(getattr(self, name)) < 1:
                raise bad(name, f"is {getattr(self, name)}; it must be a positive integer")
        if self.feat_dim % self.n_heads or self.geo_hidden[-1] % self.n_heads:
            raise bad("n_heads", f"is {self.n_heads}; it must divide feat_dim ({self.feat_dim}) "
                      f"and geo_hidden[-1] ({self.geo_hidden[-1]})")
        if not 0.0 < self.tau <= 1.0:
            raise bad("tau", f"is {self.tau}; it must lie in (0, 1] (1 = mean aggregation)")
        if self.min_source_depth <= 0.0:
            raise bad("min_source_depth", f"is {self.min_source_depth}; it must be > 0")
        if self.class_weights and (len(self.class_weights) != self.n_classes or min(self.class_weights) <= 0):
            raise bad("class_weights", f"holds {len(self.class_weights)} values (min {min(self.class_weights)}); give "
                      f"none or {self.n_classes} positive weights")
        if len(self.weight_hidden) != 2 or len(self.geo_hidden) != 2:
            raise bad("weight_hidden/geo_hidden", "must each hold exactly two widths")

    @property
    def n_fine_total(self) -> int:
        """Samples per ray seen by the fine network: n_coarse + n_fine (``union``) or n_fine (``new``)."""
        return self.n_fine + (self.n_coarse if self.fine_samples == "union" else 0)
