"""Calibrating the fast render's coarse confidence on validation rooms (``sray eval --calibrate``): a temperature
fitted to the coarse logits of their test views, rendered as scored (docs/fleet.md, "Shifted splits").
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.model.calibration import fit_temperature, nll
from sray.model.view_render import render_view, strided_pixels
from sray.platform.eval.eval_model import EvalModel
from sray.platform.eval.zero_shot import select_scenes

CALIBRATION_FILE = "calibration.json"
"""File of an evaluation's output folder holding the calibration it used."""


def coarse_logits(model: EvalModel, shards: Path, n_source: int, stride: int) -> tuple[torch.Tensor, torch.Tensor, int]:
    """(logits (N, L), labels (N,), rooms) of the coarse pass at every ``stride``-th pixel of the test views of
    every test room of ``shards``, rays no source sees (all logits -inf) left out."""
    names, _ = select_scenes(Path(shards), None)
    logits, labels = [], []
    for name in names:
        for sample in make_eval_samples(Path(shards), name, split="test", n_source=n_source):
            h, w = sample.query_label.shape
            out = render_view(model.renderer(sample), sample.query.K, sample.query.c2w, (h, w), sample.near,
                              sample.far, model.chunk, model.device, stride, None, passes=("coarse",),
                              keys=("logits",))["coarse"]["logits"].reshape(-1, model.n_classes).cpu()
            uv, _, _ = strided_pixels(h, w, stride)
            logits.append(out)
            labels.append(sample.query_label[uv[:, 1].long(), uv[:, 0].long()])
    all_logits, all_labels = torch.cat(logits), torch.cat(labels)
    seen = torch.isfinite(all_logits).all(-1)
    return all_logits[seen], all_labels[seen], len(names)


def calibrate(model: EvalModel, shards: Path, n_source: int = 8, stride: int = 4) -> dict[str, Any]:
    """The fitted temperature of ``model``'s coarse confidence on the validation shards and what it was fitted on:
    ``{"temperature", "nll_at_1", "nll_fitted", "rays", "rooms", "shards", "stride", "n_source"}``."""
    logits, labels, rooms = coarse_logits(model, shards, n_source, stride)
    temperature = fit_temperature(logits, labels, model.ignore_id)
    keep = labels != model.ignore_id
    return {"temperature": temperature, "nll_at_1": nll(logits[keep], labels[keep], 1.0),
            "nll_fitted": nll(logits[keep], labels[keep], temperature), "rays": int(keep.sum()), "rooms": rooms,
            "shards": str(Path(shards).resolve()), "stride": stride, "n_source": n_source}
