"""A linear probe on frozen encoder features: how much class information an encoder's features hold.

Fitting reads only the train scenes' source pools (each train scene's ``train`` split minus its held-out
views), at most ``max_views`` of their views spread evenly over the pools in scene order. The encoder is
frozen; its 1/4-resolution feature j is centred on image pixel 4j (``encoder.FEATURE_STRIDE``), so each
feature pixel is paired with the label of the image pixel under its centre (no resampling of labels).
The probe is the 1x1 convolution of :class:`~sray.model.source_semantics.SourceSemanticHead` fitted as a
plain (unweighted) multinomial logistic regression: full-batch Adam on every labelled feature pixel.
Prediction runs the encoder on an image and the head's centre-aligned up-sampling to full resolution.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import Manifest, read_manifest
from sray.model.config import SRayConfig
from sray.model.encoder import FEATURE_STRIDE, ResUNetEncoder
from sray.model.source_semantics import SourceSemanticHead


@dataclass
class LinearProbe:
    """A frozen encoder and the linear head fitted on its features."""

    encoder: ResUNetEncoder
    """The frozen encoder (eval mode)."""
    head: SourceSemanticHead
    """The fitted 1x1 classifier with its full-resolution up-sampling."""
    steps: int
    """Adam steps of the fit."""
    n_views: int
    """Training images the fit read."""
    n_pixels: int
    """Labelled feature pixels it was fitted on."""
    fit_seconds: float
    """Wall seconds of feature extraction and fit."""

    @torch.no_grad()
    def predict(self, rgb: Tensor) -> Tensor:
        """Class ids (B, H, W) int64 of images rgb (B, 3, H, W) in [0, 1]."""
        return self.head(self.encoder(rgb), tuple(rgb.shape[-2:])).argmax(1)

    def budget(self) -> str:
        """One line for a table: what the fit used."""
        return f"probe {self.steps} Adam steps on {self.n_pixels} feature pixels of {self.n_views} train-scene views"


def random_encoder(feat_dim: int, seed: int, width: int = 16) -> ResUNetEncoder:
    """A freshly initialised encoder of ``feat_dim`` output channels and first-layer ``width`` (PyTorch's default
    initialisation under ``seed``; the global random state is left as it was)."""
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        return ResUNetEncoder(feat_dim, width).eval()


def probe_views(manifest: Manifest, max_views: int) -> list[tuple[str, str]]:
    """(scene, view id) of at most ``max_views`` views spread evenly over the train scenes' source pools."""
    pool = [(s, v) for s, e in sorted(manifest.scenes.items()) if e.meta.get("role", "train") == "train"
            for v in source_pool(SceneMeta.from_json(e.meta))]
    if not pool:
        raise ValueError("the shard manifest has no train scene; the probe fits on train scenes only")
    picks = np.unique(np.linspace(0, len(pool) - 1, min(max_views, len(pool))).round().astype(int))
    return [pool[i] for i in picks]


@torch.no_grad()
def feature_pixels(encoder: ResUNetEncoder, shards: Path, manifest: Manifest, views: list[tuple[str, str]],
                   ignore_id: int) -> tuple[Tensor, Tensor]:
    """Features (P, C) float32 and labels (P,) int64 of every labelled feature pixel of ``views``, each feature
    pixel paired with the label at its centre pixel (FEATURE_STRIDE j, FEATURE_STRIDE i)."""
    feats, labels = [], []
    for scene in sorted({s for s, _ in views}):
        stored = read_scene_views(shards, manifest.scenes[scene])
        for _, view_id in [p for p in views if p[0] == scene]:
            rgb = torch.from_numpy(stored[view_id].rgb().astype(np.float32) / 255.0).permute(2, 0, 1)[None]
            f = encoder(rgb)[0]  # (C, h, w)
            label = torch.from_numpy(stored[view_id].label().astype(np.int64))[::FEATURE_STRIDE, ::FEATURE_STRIDE]
            keep = label.reshape(-1) != ignore_id
            feats.append(f.reshape(f.shape[0], -1).T[keep])
            labels.append(label.reshape(-1)[keep])
    return torch.cat(feats), torch.cat(labels)


def fit_probe(encoder: ResUNetEncoder, shards: Path, model_cfg: SRayConfig, *, steps: int = 300,
              max_views: int = 64, lr: float = 0.02, seed: int = 0) -> LinearProbe:
    """Fit a linear probe on ``encoder``'s frozen features (see the module doc); ``model_cfg`` gives the
    feature width, the classes and the ignore id (its class weights are not used: the fit is unweighted). The head
    starts from PyTorch's initialisation under ``seed`` (the global random state left as it was): a fit repeats."""
    start = time.perf_counter()
    shards = Path(shards)
    manifest = read_manifest(shards)
    views = probe_views(manifest, max_views)
    encoder = encoder.eval()
    x, y = feature_pixels(encoder, shards, manifest, views, model_cfg.ignore_id)  # (P, C), (P,)
    if y.numel() == 0:
        raise ValueError(f"{shards}: the {len(views)} probe views hold no labelled pixel")
    if int(y.max()) >= model_cfg.n_classes:
        raise ValueError(f"{shards}: labels up to {int(y.max())}, the model predicts {model_cfg.n_classes} classes; "
                         "probe on data of the checkpoint's label space")
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        head = SourceSemanticHead(dataclasses.replace(model_cfg, class_weights=()))
    weight = head.classify.weight  # (L, C, 1, 1)
    optimizer = torch.optim.Adam(head.parameters(), lr=lr)
    for _ in range(steps):
        loss = F.cross_entropy(F.linear(x, weight.flatten(1), head.classify.bias), y)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    return LinearProbe(encoder=encoder, head=head.eval(), steps=steps, n_views=len(views), n_pixels=int(y.numel()),
                       fit_seconds=time.perf_counter() - start)
