"""Temperature calibration (Guo et al.): the T > 0 minimising the NLL of labelled samples under softmax(logits / T),
fitted on validation rooms for the fast render's coarse confidence (``FastRender.temperature``). A grid over log T,
then golden-section search in the best cell: deterministic, exact to ``tol``."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor

T_RANGE = (0.05, 20.0)
"""Temperatures searched."""


def nll(logits: Tensor, labels: Tensor, temperature: float) -> float:
    """Mean negative log-likelihood of labels (N,) under softmax(logits (N, L) / temperature)."""
    return float(F.cross_entropy(logits.float() / temperature, labels.long()))


def fit_temperature(logits: Tensor, labels: Tensor, ignore_id: int = 255, grid: int = 61, tol: float = 1e-4) -> float:
    """The temperature in :data:`T_RANGE` minimising :func:`nll` over the samples whose label is not ``ignore_id``
    (logits (N, L), labels (N,)); ValueError when none is labelled or a logit is not finite."""
    keep = labels != ignore_id
    logits, labels = logits[keep].float(), labels[keep]
    if labels.numel() == 0:
        raise ValueError("fit_temperature: no labelled sample to calibrate on")
    if not torch.isfinite(logits).all():
        raise ValueError("fit_temperature: logits must be finite (drop rays no source view sees)")
    lo, hi = math.log(T_RANGE[0]), math.log(T_RANGE[1])
    points = [lo + (hi - lo) * i / (grid - 1) for i in range(grid)]
    values = [nll(logits, labels, math.exp(p)) for p in points]
    best = min(range(grid), key=values.__getitem__)
    a, b = points[max(best - 1, 0)], points[min(best + 1, grid - 1)]
    ratio = (math.sqrt(5) - 1) / 2
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = nll(logits, labels, math.exp(c)), nll(logits, labels, math.exp(d))
    while b - a > tol:
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = nll(logits, labels, math.exp(c))
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = nll(logits, labels, math.exp(d))
    return math.exp((a + b) / 2)
