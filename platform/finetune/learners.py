"""The per-scene learners of a fleet task behind :class:`Learner`: :class:`SRayLearner` (the shared model, only the
``adapt`` modules trainable), :class:`NeRFLearner` (a Semantic-NeRF from scratch) and :class:`TransferLearner` (the
``2d-transfer`` segmenter, finetuned whole), all updated by :class:`~sray.platform.train.step.TrainStep`; the loss is
float32 (``render_loss``; the segmenter's ``source_semantic_loss``)."""

from __future__ import annotations

import contextlib
from abc import ABC, abstractmethod
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from sray.data_tools.loader.sample_types import EvalSample, TrainSample
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.scene import SceneMeta
from sray.data_tools.shards.manifest import read_manifest
from sray.model.fast_render import FastRender
from sray.model.losses import render_loss
from sray.model.semantic_nerf import SemanticNeRF, SemanticNeRFConfig, scene_box_from_cameras
from sray.model.semantic_ray import SourceSet, SRayModel
from sray.model.view_render import RayRenderer
from sray.platform.common.model_input import ray_batch
from sray.platform.config.fleet_config import SemanticNeRFSettings
from sray.platform.eval.segmenter import Segmenter, transfer_renderer
from sray.platform.eval.view_scoring import encode_sources, sray_renderer
from sray.platform.finetune.scene_artifacts import adapted_keys, adapted_state, apply_delta, save_sray_delta, save_whole
from sray.platform.train.step import TrainStep, fused_adam


class Learner(ABC):
    """One method's network on one scene, with the shared training step ``step`` (a ``TrainStep`` over ``params``)."""

    def __init__(self, net: nn.Module, params: list[nn.Parameter], lr: float, grad_clip: float, precision: str,
                 device: torch.device, max_nonfinite_in_row: int) -> None:
        """``net`` (already on ``device``) is what the method evaluates and stores; ``params``, what it trains."""
        self.net, self.device = net, device
        self.step = TrainStep(params, fused_adam(params, lr), grad_clip, precision, device, max_nonfinite_in_row)

    @contextlib.contextmanager
    def inference(self) -> Iterator[None]:
        """Evaluate with every parameter ``requires_grad`` as in a loaded model: CPU convolutions choose their code
        path by these flags even under ``no_grad``, and the stored artifact then reproduces the scores exactly."""
        flags = [(p, p.requires_grad) for p in self.net.parameters()]
        self.net.requires_grad_(True)
        try:
            yield
        finally:
            for p, flag in flags:
                p.requires_grad_(flag)

    fast: FastRender | None = None
    """The fast render mode of the held-out renderer (None: the full render; only S-Ray has one)."""

    @abstractmethod
    def loss(self, sample: TrainSample) -> tuple[Tensor, dict[str, Tensor]]:
        """(loss, terms with at least ``psnr``) of one training sample, forward under ``self.step.autocast()``."""

    @abstractmethod
    def renderer(self, sample: EvalSample) -> RayRenderer:
        """The deterministic ray renderer of one held-out evaluation sample."""

    @abstractmethod
    def snapshot(self) -> dict[str, Tensor]:
        """CPU copy of the state the method trains."""

    @abstractmethod
    def restore(self, state: dict[str, Tensor]) -> None:
        """Put back a :meth:`snapshot`."""

    @abstractmethod
    def save(self, path: Path, scene: str) -> None:
        """Write the scene artifact (the state as it is now) to ``path``."""


class SRayLearner(Learner):
    """Trains only the modules ``adapt`` of the shared S-Ray model (the rest stays frozen)."""

    def __init__(self, net: SRayModel, base_sha256: str, adapt: tuple[str, ...], lr: float, grad_clip: float,
                 precision: str, device: torch.device, max_nonfinite_in_row: int,
                 fast: FastRender | None = None) -> None:
        net = net.to(device).eval()
        self.fast, self.base_sha256, self.adapt = fast, base_sha256, tuple(adapt)
        keys = set(adapted_keys(net, adapt))
        params = [p for name, p in net.named_parameters() if name in keys]
        for name, p in net.named_parameters():
            p.requires_grad_(name in keys)
        self.encoder_frozen = not any(k.startswith("encoder.") for k in keys)
        self._sources: dict[tuple[str, str], SourceSet] = {}
        super().__init__(net, params, lr, grad_clip, precision, device, max_nonfinite_in_row)

    def loss(self, sample: TrainSample) -> tuple[Tensor, dict[str, Tensor]]:
        """Loss of one training sample (sources encoded without gradient while the encoder is frozen)."""
        sample = sample.to(self.device)
        batch = ray_batch(sample)
        origins, dirs, near, far = batch.query.rays()
        with self.step.autocast():
            with torch.no_grad() if self.encoder_frozen else contextlib.nullcontext():
                src = self.net.encode(batch.src_rgb, batch.src_K, batch.src_c2w, batch.src_depth)
            return self.net.training_loss(src, origins, dirs, near, far, sample.target_label, sample.target_rgb)

    def renderer(self, sample: EvalSample) -> RayRenderer:
        """Ray renderer bound to the sample's fixed source views (encoded once while the encoder is frozen)."""
        if not self.encoder_frozen:
            return sray_renderer(self.net, sample, self.device, self.fast)
        key = (sample.scene, sample.query_id)
        if key not in self._sources:
            self._sources[key] = encode_sources(self.net, sample, self.device)
        return self.net.ray_renderer(self._sources[key], self.fast)

    def snapshot(self) -> dict[str, Tensor]:
        """CPU copy of the adapted tensors."""
        return adapted_state(self.net, self.adapt)

    def restore(self, state: dict[str, Tensor]) -> None:
        """Put back a :meth:`snapshot`."""
        apply_delta(self.net, state, "snapshot")

    def save(self, path: Path, scene: str) -> None:
        """Write the scene artifact (the adapted tensors as they are now + the base checksum)."""
        save_sray_delta(path, self.snapshot(), self.base_sha256, self.adapt, scene)


class WholeNetLearner(Learner):
    """A learner that trains every parameter of its network and stores it whole as a scene artifact."""

    method: str

    def __init__(self, net: nn.Module, lr: float, grad_clip: float, precision: str, device: torch.device,
                 max_nonfinite_in_row: int) -> None:
        net = net.to(device).eval()
        super().__init__(net, list(net.parameters()), lr, grad_clip, precision, device, max_nonfinite_in_row)

    def snapshot(self) -> dict[str, Tensor]:
        """CPU copy of the whole state dict."""
        return {k: v.detach().to("cpu", copy=True) for k, v in self.net.state_dict().items()}

    def restore(self, state: dict[str, Tensor]) -> None:
        """Put back a :meth:`snapshot`."""
        self.net.load_state_dict(state)

    def save(self, path: Path, scene: str) -> None:
        """Write the scene artifact: the whole network as it is now, with its config."""
        save_whole(path, self.net, scene, self.method)


class NeRFLearner(WholeNetLearner):
    """Trains a Semantic-NeRF of the scene from scratch (every parameter)."""

    method = "semantic-nerf"

    def loss(self, sample: TrainSample) -> tuple[Tensor, dict[str, Tensor]]:
        """Loss of one training sample's rays (its source views are not used)."""
        origins, dirs, near, far = ray_batch(sample).query.to(self.device).rays()
        with self.step.autocast():
            out = self.net.render_rays(origins, dirs, near, far, stratified=True)
        return render_loss(out, sample.target_label.to(self.device), sample.target_rgb.to(self.device), self.net.cfg)

    def renderer(self, sample: EvalSample) -> RayRenderer:
        """Ray renderer (deterministic samples)."""
        return lambda o, d, near, far: self.net.render_rays(o, d, near, far, stratified=False)


class TransferLearner(WholeNetLearner):
    """Finetunes the 2D segmenter of ``2d-transfer`` (every parameter) on labelled images of the scene."""

    method = "2d-transfer"

    def __init__(self, net: Segmenter, lr: float, grad_clip: float, precision: str, device: torch.device,
                 max_nonfinite_in_row: int, tolerance: float) -> None:
        """``tolerance``: the relative depth agreement of the held-out transfer's occlusion test."""
        super().__init__(net, lr, grad_clip, precision, device, max_nonfinite_in_row)
        self.tolerance = tolerance

    def loss(self, sample: TrainSample) -> tuple[Tensor, dict[str, Tensor]]:
        """Class-weighted cross-entropy on the source images (m, 3, H, W) and labels (m, H, W); ``psnr`` is NaN."""
        sources = sample.sources.to(self.device)
        if sources.label is None:
            raise ValueError("2d-transfer trains on labelled source images: build its loader with source_labels "
                             "(SceneSetup.source_labels=True)")
        with self.step.autocast():
            loss = self.net.loss(sources.rgb, sources.label)
        return loss, {"ce": loss.detach(), "psnr": torch.full((), float("nan"), device=self.device)}

    def renderer(self, sample: EvalSample) -> RayRenderer:
        """The segmenter's labels of the sample's source views carried into its query view by their depth."""
        return transfer_renderer(self.net, sample, self.tolerance, self.device)


def build_semantic_nerf(shards: Path, scene: str, n_classes: int, ignore_id: int, n_coarse: int, n_fine: int,
                        nerf: SemanticNeRFSettings, seed: int, chunk: int) -> SemanticNeRF:
    """A fresh Semantic-NeRF (seeded) whose scene box covers the frusta of all the scene's split views."""
    entry = read_manifest(shards).scenes[scene]
    meta, views = SceneMeta.from_json(entry.meta), read_scene_views(shards, entry)
    ids = [v for v in meta.view_ids if any(v in s for s in meta.splits.values())]
    K = torch.from_numpy(np.stack([views[v].K for v in ids]))  # (V, 3, 3)
    c2w = torch.from_numpy(np.stack([views[v].c2w for v in ids]))  # (V, 4, 4)
    center, scale = scene_box_from_cameras(K, c2w, tuple(entry.image_size), meta.near, meta.far)
    torch.manual_seed(seed)
    return SemanticNeRF(SemanticNeRFConfig(
        n_classes=n_classes, pos_freqs=nerf.pos_freqs, dir_freqs=nerf.dir_freqs, depth=nerf.depth, width=nerf.width,
        skip_layer=nerf.skip_layer, n_coarse=n_coarse, n_fine=n_fine, ignore_id=ignore_id, chunk=chunk,
        scene_center=center, scene_scale=scale))
