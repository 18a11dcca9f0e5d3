"""The plain 2D segmenter (S-Ray's encoder, source-view head and loss, ``sray.model.source_semantics``, trained alone)
and its ``2d-transfer`` prediction: its labels and colours of the source images splatted into the query by the SOURCE
depth (``label_transfer``, ``forward``; docs/fleet.md, "2D label transfer"). A segmenter is a folder:
``segmenter.pt`` (the state dict, ``weights_only``-safe) and ``segmenter.json`` (its config and training record)."""

from __future__ import annotations

import io
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import Tensor, nn

from sray.data_tools.atomic import atomic_write_bytes, atomic_write_json
from sray.data_tools.loader.sample_types import EvalSample, QueryCamera, SourceViews
from sray.model.config import SRayConfig
from sray.model.encoder import ResUNetEncoder
from sray.model.source_semantics import SourceSemanticHead, source_semantic_loss
from sray.model.view_render import RayRenderer
from sray.platform.checkpoints.folders import load_checkpoint, read_meta
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.config.stored_format import from_plain, outdated
from sray.platform.eval.label_transfer import UNSEEN, LabelTransfer, nearest_pixel, project_points, transfer_labels

WEIGHTS_FILE = "segmenter.pt"
CONFIG_FILE = "segmenter.json"


@dataclass(frozen=True)
class SegmenterConfig:
    """What builds a segmenter network (stored beside its weights)."""

    n_classes: int
    """Classes L of the label space it predicts."""
    feat_dim: int = 32
    """Channels of the encoder's features (S-Ray's ``model.feat_dim``)."""
    encoder_width: int = 16
    """Channels of the encoder's first layer (S-Ray's ``model.encoder_width``)."""
    ignore_id: int = 255
    """Label id of unlabelled pixels (never a target)."""
    class_weights: tuple[float, ...] = ()
    """Per-class weights of the training cross-entropy (empty = unweighted)."""

    def head_config(self) -> SRayConfig:
        """The S-Ray config whose ``SourceSemanticHead`` and ``source_semantic_loss`` this segmenter uses."""
        return SRayConfig(n_classes=self.n_classes, feat_dim=self.feat_dim, ignore_id=self.ignore_id,
                          class_weights=tuple(self.class_weights))


class Segmenter(nn.Module):
    """RGB (B, 3, H, W) in [0, 1] -> class logits (B, L, H, W): ResUNet encoder + linear per-pixel head."""

    def __init__(self, cfg: SegmenterConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.encoder = ResUNetEncoder(cfg.feat_dim, cfg.encoder_width)
        self.head = SourceSemanticHead(cfg.head_config())

    def forward(self, rgb: Tensor) -> Tensor:
        """Logits (B, L, H, W) of images rgb (B, 3, H, W) in [0, 1]."""
        return self.head(self.encoder(rgb), tuple(rgb.shape[-2:]))

    def loss(self, rgb: Tensor, labels: Tensor) -> Tensor:
        """Mean class-weighted cross-entropy of images rgb (B, 3, H, W) against labels (B, H, W) int64."""
        return source_semantic_loss(self(rgb), labels, self.cfg.head_config())

    @torch.no_grad()
    def predict(self, rgb: Tensor, batch: int = 4) -> Tensor:
        """Argmax class ids (B, H, W) int64 of images rgb (B, 3, H, W), ``batch`` images per forward pass."""
        return torch.cat([self(rgb[i:i + batch]).argmax(1) for i in range(0, rgb.shape[0], batch)])


@dataclass
class SegmenterRecord:
    """A saved segmenter: its network config and the account of its training."""

    config: SegmenterConfig
    training: dict[str, Any] = field(default_factory=dict)
    """Budget and spend (``cpu_seconds_budget``, ``cpu_seconds``, ``steps``, ``images``), data, seed, optimiser."""

    def budget(self) -> str:
        """One line for a table: the CPU seconds and steps it trained for (or its S-Ray checkpoint's step and CPU)."""
        t = self.training
        if "checkpoint" in t:
            return (f"S-Ray's encoder + source-view head, checkpoint step {t['steps']} "
                    f"({t['cpu_seconds']:.0f} CPU s of pretraining)")
        spent, steps, images = t.get("cpu_seconds", 0.0), t.get("steps", 0), t.get("images", 0)
        return f"segmenter {spent:.0f} CPU s, {steps} steps of {images} images"


def save_segmenter(model: Segmenter, training: dict[str, Any], out: Path) -> Path:
    """Write ``model``'s weights and config (plus ``training``) into folder ``out`` atomically; returns ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    torch.save({k: v.detach().cpu() for k, v in model.state_dict().items()}, buffer)
    atomic_write_bytes(out / WEIGHTS_FILE, buffer.getvalue())
    atomic_write_json(out / CONFIG_FILE, {"config": asdict(model.cfg), "training": training})
    return out


def load_segmenter(folder: Path, map_location: str | torch.device = "cpu") -> tuple[Segmenter, SegmenterRecord]:
    """The segmenter (eval mode) saved in ``folder`` and its record; errors name the file and the fix."""
    folder = Path(folder)
    for name in (CONFIG_FILE, WEIGHTS_FILE):
        if not (folder / name).exists():
            raise FileNotFoundError(f"{folder / name}: missing; train a segmenter with `sray bench segmenter "
                                    f"--data SHARDS --cpu-seconds S --out {folder}`")
    stored = json.loads((folder / CONFIG_FILE).read_text())
    if "encoder_norm" in stored["config"]:
        raise outdated(f"{folder / CONFIG_FILE}: this segmenter", "1 (with encoder_norm)", "2")
    record = SegmenterRecord(from_plain(SegmenterConfig, stored["config"], f"{folder / CONFIG_FILE}: config"),
                             stored.get("training", {}))
    model = Segmenter(record.config)
    model.load_state_dict(torch.load(folder / WEIGHTS_FILE, map_location=map_location, weights_only=True))
    return model.eval(), record


def segmenter_from_checkpoint(checkpoint: Path, out: Path) -> tuple[Segmenter, SegmenterRecord]:
    """Write an S-Ray checkpoint's encoder and source-view head as a segmenter folder ``out``; it and its record."""
    checkpoint = Path(checkpoint)
    net, cfg = model_from_checkpoint(checkpoint)
    if net.src_head is None:
        raise ValueError(f"{checkpoint}: its model has no source-view head (model.lambda_src_sem = 0 in its config); "
                         "export a checkpoint trained with the source-view loss, or train a segmenter with "
                         "`sray bench segmenter --data SHARDS --cpu-seconds S --out DIR`")
    m = cfg.model
    seg = Segmenter(SegmenterConfig(n_classes=m.n_classes, feat_dim=m.feat_dim, encoder_width=m.encoder_width,
                                    ignore_id=m.ignore_id, class_weights=tuple(m.class_weights)))
    seg.encoder.load_state_dict(net.encoder.state_dict())
    seg.head.load_state_dict(net.src_head.state_dict())
    counters = load_checkpoint(checkpoint)["counters"]
    training = {"checkpoint": str(checkpoint.resolve()), "steps": int(read_meta(checkpoint)["step"]),
                "cpu_seconds": float(counters["cpu_seconds"]), "recipe": cfg.recipe}
    save_segmenter(seg, training, out)
    return seg.eval(), SegmenterRecord(seg.cfg, training)


def source_depth_transfer(labels: Tensor, sources: SourceViews, query: QueryCamera, tolerance: float,
                          ignore_id: int, source_rgb: Tensor | None = None) -> LabelTransfer:
    """Per-source labels (m, H, W) int64 splatted into the query camera's (H, W) image by the sources' depth;
    ``source_rgb`` (m, 3, H, W): carry those colours too. ValueError when the sources carry no depth."""
    if sources.depth is None:
        raise ValueError("2d-transfer: the source views carry no depth; it carries labels by the source depth, "
                         "so evaluate shards written with depth (every sray shard holds it)")
    return transfer_labels(labels, sources.K, sources.c2w, sources.depth, query.K, query.c2w,
                           tuple(sources.depth.shape[-2:]), "forward", tolerance=tolerance, ignore_id=ignore_id,
                           source_rgb=source_rgb)


@torch.no_grad()
def segment_and_transfer(segmenter: Segmenter, sources: SourceViews, query: QueryCamera,
                         tolerance: float) -> LabelTransfer:
    """The segmenter's labels of the source images (m, 3, H, W), with their colours, carried into the query view."""
    labels = segmenter.predict(sources.rgb)  # (m, H, W)
    return source_depth_transfer(labels, sources, query, tolerance, segmenter.cfg.ignore_id, source_rgb=sources.rgb)


def pixel_lookup_renderer(transfer: LabelTransfer, query: QueryCamera, n_classes: int) -> RayRenderer:
    """A ray renderer over the transferred maps of the query camera: each ray reads the nearest pixel, ``logits``
    (R, L) 0 at its label and -inf elsewhere (all -inf without one), ``rgb`` (R, 3) its carried colour (0 there)."""
    if transfer.rgb is None:
        raise ValueError("2d-transfer: pass the source colours to the transfer; its renderer returns them")
    hw = (int(transfer.labels.shape[0]), int(transfer.labels.shape[1]))
    labels, colours = transfer.labels.reshape(-1), transfer.rgb.reshape(-1, 3)  # (Hq*Wq,), (Hq*Wq, 3)

    def render(origins: Tensor, dirs: Tensor, near: Tensor, far: Tensor) -> dict[str, dict[str, Tensor]]:
        uv, z = project_points(origins + dirs, query.K[None], query.c2w[None])  # (1, R, 2), (1, R)
        index, inside = nearest_pixel(uv[0], hw)  # (R,)
        hit = inside & (z[0] > 0)  # (R,) the ray meets a pixel of the image
        label = torch.where(hit, labels[index], torch.full_like(index, UNSEEN))  # (R,)
        known = label != UNSEEN
        logits = torch.full((len(label), n_classes), float("-inf"), device=label.device)  # (R, L)
        logits[known, label[known]] = 0.0
        rgb = torch.where(hit[:, None], colours[index], torch.zeros_like(colours[index]))  # (R, 3)
        out = {"logits": logits, "rgb": rgb}  # (R, L), (R, 3)
        return {"coarse": out, "fine": out}

    return render


def transfer_renderer(segmenter: Segmenter, sample: EvalSample, tolerance: float,
                      device: torch.device) -> RayRenderer:
    """The ``2d-transfer`` ray renderer of one sample: segmented and splatted once on ``device``, then read per ray."""
    sources, query = sample.sources.to(device), sample.query.to(device)
    return pixel_lookup_renderer(segment_and_transfer(segmenter, sources, query, tolerance), query,
                                 segmenter.cfg.n_classes)
