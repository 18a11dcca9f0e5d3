"""A training batch's loss computed piece by piece: the same loss and gradients, a fraction of the memory. Each
piece's terms are scaled by its share of the batch and its gradient taken at once; :class:`_PrecomputedGradLoss`
hands the gathered gradients back on ``loss.backward()`` (one encoder backward, DDP hooks, loss scaling intact)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import torch
from torch import Tensor, nn

from .losses import LossSettings, LossShares, labelled_weights, psnr_from_mse, render_loss
from .source_set import SourceSet

PieceRenderer = Callable[[SourceSet, slice], dict[str, dict[str, Tensor]]]
"""(sources, slice of the batch's rays) -> that piece's ``render_rays`` output."""


class _PrecomputedGradLoss(torch.autograd.Function):
    """A scalar loss of (features, *params) whose gradients were computed while evaluating it."""

    @staticmethod
    def forward(ctx: Any, evaluate: Callable[[Tensor], tuple[Tensor, list[Tensor | None]]], feats: Tensor,
                *params: Tensor) -> Tensor:
        """Run ``evaluate(feats)`` -> (loss, its gradients for [feats, *params]), keeping the gradients."""
        loss, grads = evaluate(feats)
        ctx.grads = grads
        return loss

    @staticmethod
    def backward(ctx: Any, grad_loss: Tensor) -> tuple[Tensor | None, ...]:
        """The kept gradients times the incoming one (a loss scaler's scale, or 1)."""
        return (None, *(None if g is None else g * grad_loss for g in ctx.grads))


def _piece_shares(weights: Tensor, pieces: list[slice]) -> Tensor:
    """(P,) each piece's share of the batch's total ``weights`` (R,); all 0 when the total is 0."""
    total = weights.sum()
    return torch.stack([weights[sl].sum() for sl in pieces]) / torch.where(total > 0, total, torch.ones_like(total))


def piecewise_render_loss(render: PieceRenderer, src: SourceSet, params: list[nn.Parameter], n_rays: int,
                          piece: int, target_label: Tensor, target_rgb: Tensor,
                          cfg: LossSettings) -> tuple[Tensor, dict[str, Tensor]]:
    """``render_loss`` of ``n_rays`` rays rendered ``piece`` rays at a time by ``render(src, slice)``, with one pass's
    gradients to ``src.feats`` and ``params`` (the network outside the encoder); target_label (R,) int64, target_rgb
    (R, 3). Returns the scalar loss (its backward delivers them; none kept without grad mode) and the batch's terms."""
    pieces = [slice(start, min(start + piece, n_rays)) for start in range(0, n_rays, piece)]
    sem_shares = _piece_shares(labelled_weights(target_label, cfg), pieces)  # (P,)
    ray_shares = target_rgb.new_tensor([sl.stop - sl.start for sl in pieces], dtype=torch.float32) / n_rays  # (P,)
    wants_grad = torch.is_grad_enabled() and (src.feats.requires_grad or any(p.requires_grad for p in params))
    summed: dict[str, Tensor] = {}

    def evaluate(feats: Tensor) -> tuple[Tensor, list[Tensor | None]]:
        leaf = feats.detach().requires_grad_(feats.requires_grad)
        piece_src = dataclasses.replace(src, feats=leaf)
        inputs = [t for t in (leaf, *params) if t.requires_grad]
        grads: list[Tensor | None] = [None] * len(inputs)
        loss = target_rgb.new_zeros((), dtype=torch.float32)
        with torch.enable_grad() if wants_grad else torch.no_grad():
            for i, sl in enumerate(pieces):
                shares = LossShares(sem_shares[i], ray_shares[i])
                piece_loss, terms = render_loss(render(piece_src, sl), target_label[sl], target_rgb[sl], cfg, shares)
                if wants_grad:
                    got = torch.autograd.grad(piece_loss, inputs, allow_unused=True)
                    grads = [g if a is None else a if g is None else a + g for a, g in zip(grads, got)]
                loss = loss + piece_loss.detach()
                for key, value in terms.items():
                    summed[key] = summed[key] + value if key in summed else value
        grad_of = {id(t): g for t, g in zip(inputs, grads)}
        return loss, [grad_of.get(id(t)) for t in (leaf, *params)]

    if wants_grad:
        loss = _PrecomputedGradLoss.apply(evaluate, src.feats, *params)
    else:
        loss = evaluate(src.feats)[0]
    last = "fine" if "rgb_fine" in summed else "coarse"
    summed["psnr"] = psnr_from_mse(summed[f"rgb_{last}"])
    return loss, summed
