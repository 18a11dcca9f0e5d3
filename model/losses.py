"""Training objective of S-Ray and Semantic-NeRF (the paper's appendix), in float32 whatever the autocast region:
``L_total = lambda_sem * L_sem + lambda_rgb * L_rgb``; ``L_sem = CE(coarse logits) + CE(fine logits)``, each the mean
cross-entropy over the labelled rays (target != ignore id; 0 with a zero gradient when there is none; with
``class_weights`` w, ``sum_i w[y_i] CE_i / sum_i w[y_i]``); ``L_rgb = MSE(coarse rgb) + MSE(fine rgb)`` over all rays.
Label ids outside [0, L) are refused by the loader, here only with ``SRAY_DEBUG_CHECKS=1`` (a device sync)."""

from __future__ import annotations

from typing import NamedTuple, Protocol

import torch
import torch.nn.functional as F
from torch import Tensor

from . import debug_checks

PASSES = ("coarse", "fine")
"""Render passes in the order the loss sums them (docs/CONTRACTS.md)."""


class LossSettings(Protocol):
    """What ``render_loss`` reads from a config (SRayConfig and SemanticNeRFConfig qualify)."""

    lambda_sem: float
    lambda_rgb: float
    ignore_id: int
    # optional: ``class_weights: tuple[float, ...]`` (per-class CE weights; absent or empty = unweighted)


class LossShares(NamedTuple):
    """One piece's shares of its batch (``piecewise_loss``), each a () tensor: every term of the piece is
    multiplied by its share, so the pieces' losses and terms sum to the batch's."""

    sem: Tensor
    """Share of the batch's labelled weight (the semantic terms)."""
    rgb: Tensor
    """Share of the batch's rays (the photometric terms)."""


def psnr_from_mse(mse: Tensor) -> Tensor:
    """Peak signal-to-noise ratio in dB for signals in [0, 1]: -10 log10(mse); inf when mse = 0."""
    return -10.0 * torch.log10(mse)


def labelled_cross_entropy(logits: Tensor, target: Tensor, ignore_id: int, weight: Tensor | None = None) -> Tensor:
    """Mean cross-entropy over the labelled entries: logits (N, L), target (N,) int64 with ``ignore_id`` for
    unlabelled; the sum is divided by their count, or with class weights ``weight`` (L,) their total weight. No
    boolean indexing (no device sync); exactly 0 with a zero gradient when nothing is labelled."""
    summed = F.cross_entropy(logits.float(), target, weight=weight, ignore_index=ignore_id, reduction="sum")
    if weight is None:
        return summed / (target != ignore_id).sum().clamp_min(1).to(summed.dtype)
    total = _ray_weights(target, ignore_id, weight).sum()  # (R,) -> ()
    return summed / torch.where(total > 0, total, torch.ones_like(total))


def _class_weights(cfg: LossSettings, device: torch.device) -> Tensor | None:
    """The config's per-class weights (L,) on ``device``, None when it has none."""
    weights = getattr(cfg, "class_weights", ())
    return torch.tensor(weights, dtype=torch.float32, device=device) if weights else None


def _ray_weights(target: Tensor, ignore_id: int, weight: Tensor | None) -> Tensor:
    """(R,) float32 weight of each ray in the semantic mean: 0 unlabelled, else its class's weight or 1."""
    labelled = target != ignore_id  # (R,)
    if weight is None:
        return labelled.float()
    return torch.where(labelled, weight[torch.where(labelled, target, 0)], 0.0)


def render_loss(out: dict[str, dict[str, Tensor]], target_label: Tensor, target_rgb: Tensor, cfg: LossSettings,
                shares: LossShares | None = None) -> tuple[Tensor, dict[str, Tensor]]:
    """Semantic + photometric loss of ``render_rays``' passes (``coarse`` alone without a fine pass), each with
    ``logits`` (R, L) and ``rgb`` (R, 3); target_label (R,) int64 (``cfg.ignore_id``: unlabelled), target_rgb (R, 3)
    in [0, 1]. Returns the scalar total and detached ``sem_<pass>``, ``rgb_<pass>``, ``n_labelled`` and ``psnr`` (last
    pass's colour). With ``shares`` (a batch piece's, :class:`LossShares`) every term is scaled, ``psnr`` left out."""
    passes = [p for p in PASSES if p in out]
    if not passes:
        raise ValueError("sray.model.losses.render_loss: `out` holds neither a 'coarse' nor a 'fine' pass; pass a "
                         "model's render_rays output unchanged.")
    n_rays, n_classes = out[passes[0]]["logits"].shape
    if target_label.shape != (n_rays,) or target_rgb.shape != (n_rays, 3):
        raise ValueError(f"sray.model.losses.render_loss: expected target_label ({n_rays},) and target_rgb ({n_rays}, "
                         f"3) for {n_rays} rendered rays, got {tuple(target_label.shape)} and "
                         f"{tuple(target_rgb.shape)}.")
    if target_label.dtype != torch.int64:
        raise ValueError(f"sray.model.losses.render_loss: target_label must be int64, got {target_label.dtype}.")
    mask = target_label != cfg.ignore_id  # (R,)
    n_labelled = mask.sum()
    bad = mask & ((target_label < 0) | (target_label >= n_classes)) if debug_checks.ENABLED else None
    if bad is not None and bool(bad.any()):
        raise ValueError(f"sray.model.losses.render_loss: label ids must lie in [0, {n_classes}) or equal the ignore "
                         f"id {cfg.ignore_id}; found {sorted(set(target_label[bad].tolist()))[:5]}. Check the scene's "
                         "label space against the model's n_classes.")
    with torch.autocast(device_type=target_rgb.device.type, enabled=False):
        rgb_target = target_rgb.float()
        terms: dict[str, Tensor] = {}
        sem_total = rgb_total = rgb_target.new_zeros(())
        weight = _class_weights(cfg, rgb_target.device)  # (L,) or None
        for name in passes:
            sem = labelled_cross_entropy(out[name]["logits"], target_label, cfg.ignore_id, weight)
            rgb = F.mse_loss(out[name]["rgb"].float(), rgb_target)
            if shares is not None:
                sem, rgb = sem * shares.sem, rgb * shares.rgb
            sem_total, rgb_total = sem_total + sem, rgb_total + rgb
            terms[f"sem_{name}"], terms[f"rgb_{name}"] = sem.detach(), rgb.detach()
        total = cfg.lambda_sem * sem_total + cfg.lambda_rgb * rgb_total
    terms["n_labelled"] = n_labelled.detach()
    if shares is None:
        terms["psnr"] = psnr_from_mse(terms[f"rgb_{passes[-1]}"])
    return total, terms


def labelled_weights(target_label: Tensor, cfg: LossSettings) -> Tensor:
    """(R,) float32 weight of each ray in the semantic mean: 0 unlabelled, else its class weight or 1."""
    return _ray_weights(target_label, cfg.ignore_id, _class_weights(cfg, target_label.device))
