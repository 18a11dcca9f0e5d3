"""Cross-Reprojection Attention (CRA) over the contextual space M (R rays, m views, N samples, C channels): the
stages of ``attention_variants``, intra-view after adding an embedding of each sample's normalised depth (depth, not
rank, which differs per ray in the fine pass). Each stage is an ``AttentionBlock``: pre-norm residual multi-head
attention, no feed-forward (the appendix lists none). Invalid projections are masked as keys; a sequence with no
valid key attends over all of them (finite); outputs at invalid tokens are finite, ignored downstream, not zeroed."""

from __future__ import annotations

from collections.abc import Callable

import torch.nn.functional as F
from torch import Tensor, nn

from .attention_variants import ATTENTION_VARIANTS, POSITION_STAGES
from .config import SRayConfig
from .positional_encoding import PositionalEncoding


class AttentionBlock(nn.Module):
    """Pre-norm multi-head self-attention with key masking."""

    def __init__(self, dim: int, heads: int) -> None:
        super().__init__()
        if dim % heads:
            raise ValueError(f"sray.model.cra.AttentionBlock: heads ({heads}) must divide dim ({dim}).")
        self.heads = heads
        self.norm = nn.LayerNorm(dim)
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)

    def forward(self, x: Tensor, valid: Tensor) -> Tensor:
        """x: (B, L, D) tokens; valid: (B, L) bool. Returns (B, L, D); finite at invalid tokens."""
        b, n, d = x.shape
        qkv = self.qkv(self.norm(x)).view(b, n, 3, self.heads, d // self.heads)
        q, k, v = qkv.permute(2, 0, 3, 1, 4).unbind(0)  # 3 x (B, heads, L, d / heads)
        keys = valid | ~valid.any(-1, keepdim=True)  # (B, L): all keys where none is valid
        att = F.scaled_dot_product_attention(q, k, v, attn_mask=keys[:, None, None, :])
        return x + self.proj(att.transpose(1, 2).reshape(b, n, d))  # (B, L, D)


def _over_samples(block: AttentionBlock, x: Tensor, valid: Tensor) -> Tensor:
    """``intra``: attention over the N samples of each (ray, view). x (R, m, N, C), valid (R, m, N)."""
    r, m, n, c = x.shape
    return block(x.reshape(r * m, n, c), valid.reshape(r * m, n)).view(r, m, n, c)


def _over_views(block: AttentionBlock, x: Tensor, valid: Tensor) -> Tensor:
    """``cross``: attention over the m views of each (ray, sample)."""
    r, m, n, c = x.shape
    xt = x.transpose(1, 2).reshape(r * n, m, c)  # (R*N, m, C)
    vt = valid.transpose(1, 2).reshape(r * n, m)
    return block(xt, vt).view(r, n, m, c).transpose(1, 2)


def _over_ray(block: AttentionBlock, x: Tensor, valid: Tensor) -> Tensor:
    """``dense``: one attention over all m * N tokens of a ray."""
    r, m, n, c = x.shape
    return block(x.reshape(r, m * n, c), valid.reshape(r, m * n)).view(r, m, n, c)


STAGES: dict[str, Callable[[AttentionBlock, Tensor, Tensor], Tensor]] = {
    "intra": _over_samples, "cross": _over_views, "dense": _over_ray}
"""How each stage of ``attention_variants`` groups the tokens of M for its attention block."""


class CrossReprojectionAttention(nn.Module):
    """M (R, m, N, C) -> M'' (R, m, N, C) by the stages of ``cfg.attention``, each block named after its stage."""

    def __init__(self, cfg: SRayConfig) -> None:
        super().__init__()
        self.variant = cfg.attention
        self.stages = ATTENTION_VARIANTS[cfg.attention]
        c, h = cfg.feat_dim, cfg.n_heads
        self.depth_embedding: nn.Module | None = None
        if POSITION_STAGES & set(self.stages):
            encoding = PositionalEncoding(1, cfg.depth_freqs)
            self.depth_embedding = nn.Sequential(encoding, nn.Linear(encoding.out_dim, c))
        for stage in dict.fromkeys(self.stages):
            self.add_module(stage, AttentionBlock(c, h))

    def position_signal(self, depth01: Tensor) -> Tensor:
        """The embedding added to every view's token of a sample: depth01 (R, N) in [0, 1] -> (R, N, C)."""
        if self.depth_embedding is None:
            raise ValueError(f"sray.model.cra: the {self.variant!r} variant adds no position signal.")
        return self.depth_embedding(depth01.float()[..., None])

    def forward(self, space: Tensor, valid: Tensor, depth01: Tensor) -> Tensor:
        """space (R, m, N, C), valid (R, m, N), depth01 (R, N) in [0, 1] -> (R, m, N, C), meaningful where valid."""
        r, m, n, c = space.shape
        if depth01.shape != (r, n):
            raise ValueError(f"sray.model.cra: depth01 must be ({r}, {n}), got {tuple(depth01.shape)}.")
        x = space
        if self.depth_embedding is not None:  # same signal for every view (no view embedding)
            x = x + self.position_signal(depth01)[:, None].to(x.dtype)
        for stage in self.stages:
            x = STAGES[stage](getattr(self, stage), x, valid)
        return x
