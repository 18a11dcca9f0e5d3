"""A scene's finetune artifact (safetensors): S-Ray's adapted tensors bound to the base's sha256, or a whole network."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import torch
from safetensors import safe_open
from safetensors.torch import save
from torch import Tensor, nn

from sray.data_tools.atomic import atomic_write_bytes
from sray.data_tools.shards.manifest import sha256_file
from sray.model.semantic_nerf import SemanticNeRF, SemanticNeRFConfig
from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.folders import STATE_FILE
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.config.stored_format import outdated
from sray.platform.eval.segmenter import Segmenter, SegmenterConfig

FORMAT = "sray-scene-delta"
VERSION = "1"


def state_file(checkpoint: Path) -> Path:
    """The ``state.pt`` of a checkpoint folder (or the file itself); FileNotFoundError if missing."""
    path = Path(checkpoint)
    file = path / STATE_FILE if path.is_dir() else path
    if not file.is_file():
        raise FileNotFoundError(f"{file}: missing; pass a checkpoint folder step_XXXXXXXXX holding {STATE_FILE}")
    return file


def checkpoint_sha256(checkpoint: Path) -> str:
    """Hex sha256 of a checkpoint's ``state.pt``: the identity a scene artifact is bound to."""
    return sha256_file(state_file(checkpoint))


def model_bytes(model: nn.Module) -> int:
    """Bytes of a model's state-dict tensors (parameters and buffers), without optimiser state."""
    return sum(t.numel() * t.element_size() for t in model.state_dict().values())


def adapted_keys(model: nn.Module, adapt: tuple[str, ...] | list[str]) -> list[str]:
    """State-dict keys under the module paths ``adapt``; ValueError names a path matching nothing."""
    keys = list(model.state_dict().keys())
    chosen: list[str] = []
    for prefix in adapt:
        hits = [k for k in keys if k == prefix or k.startswith(prefix + ".")]
        if not hits:
            modules = sorted({k.rsplit(".", 2)[0] for k in keys if not k.startswith("encoder.")})
            raise ValueError(f"finetune.adapt: {prefix!r} names no part of {type(model).__name__}; "
                             f"e.g. {', '.join(modules[:12])}, encoder")
        chosen += [k for k in hits if k not in chosen]
    return chosen


def adapted_state(model: nn.Module, adapt: tuple[str, ...] | list[str]) -> dict[str, Tensor]:
    """Detached CPU copies of the tensors under ``adapt`` (what a scene artifact stores)."""
    state = model.state_dict()
    return {k: state[k].detach().to("cpu", copy=True).contiguous() for k in adapted_keys(model, adapt)}


def _atomic_save(tensors: dict[str, Tensor], metadata: dict[str, str], path: Path) -> int:
    """Write a safetensors file under a temporary name, then rename; returns its size in bytes."""
    path = Path(path)
    atomic_write_bytes(path, save({k: v.contiguous() for k, v in tensors.items()}, metadata=metadata))
    return path.stat().st_size


def _read(path: Path, method: str) -> tuple[dict[str, Tensor], dict[str, str]]:
    """Tensors and metadata of an artifact ``method`` wrote; errors name the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no scene artifact here; run `sray finetune-fleet` first")
    with safe_open(str(path), framework="pt") as f:
        metadata = dict(f.metadata() or {})
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    if metadata.get("format") != FORMAT:
        raise ValueError(f"{path}: field 'format' is {metadata.get('format')!r}, expected {FORMAT!r}; "
                         "not an sray scene artifact")
    if metadata.get("method") != method:
        raise ValueError(f"{path}: field 'method' is {metadata.get('method')!r}, expected {method!r}"
                         + ("; this is not an S-Ray scene artifact (a Semantic-NeRF one loads with load_semantic_nerf)"
                            if method == "sray" else ""))
    return tensors, metadata


def save_sray_delta(path: Path, tensors: dict[str, Tensor], base_sha256: str, adapt: tuple[str, ...] | list[str],
                    scene: str) -> int:
    """Write an S-Ray scene artifact (the adapted tensors of :func:`adapted_state`); returns its bytes."""
    metadata = {"format": FORMAT, "version": VERSION, "method": "sray", "scene": scene,
                "base_sha256": base_sha256, "adapt": json.dumps(list(adapt))}
    return _atomic_save(tensors, metadata, path)


def read_sray_delta(path: Path) -> tuple[dict[str, Tensor], dict[str, str]]:
    """The tensors and metadata (``base_sha256``, ``adapt`` as JSON, ``scene``) of an S-Ray artifact."""
    return _read(path, "sray")


def apply_delta(model: nn.Module, tensors: dict[str, Tensor], where: str) -> None:
    """Copy artifact tensors into ``model`` in place; ValueError on an unknown key or a shape mismatch."""
    state = model.state_dict()
    for key, value in tensors.items():
        if key not in state:
            raise ValueError(f"{where}: tensor {key!r} is not part of {type(model).__name__}; the artifact "
                             "belongs to a different network configuration")
        if state[key].shape != value.shape:
            raise ValueError(f"{where}: tensor {key!r} has shape {tuple(value.shape)}, the model's is "
                             f"{tuple(state[key].shape)}; the artifact belongs to a different configuration")
    with torch.no_grad():
        for key, value in tensors.items():
            state[key].copy_(value)


def load_scene_model(base_checkpoint: Path, artifact: Path, map_location: str = "cpu") -> SRayModel:
    """The finetuned S-Ray model of one scene (eval mode); ValueError when the artifact is of another checkpoint."""
    tensors, metadata = read_sray_delta(artifact)
    actual = checkpoint_sha256(base_checkpoint)
    if metadata.get("base_sha256") != actual:
        raise ValueError(f"{artifact}: base checksum mismatch: the artifact was finetuned from a checkpoint with "
                         f"sha256 {metadata.get('base_sha256')}, but {state_file(base_checkpoint)} has {actual}; load "
                         "it onto the checkpoint the fleet was run with")
    model, _ = model_from_checkpoint(base_checkpoint, map_location)
    apply_delta(model, tensors, str(artifact))
    return model.eval()


def save_whole(path: Path, model: SemanticNeRF | Segmenter, scene: str, method: str) -> int:
    """Write a whole-model scene artifact (state dict + config) of ``method``; returns its bytes."""
    tensors = {k: v.detach().to("cpu", copy=True) for k, v in model.state_dict().items()}
    metadata = {"format": FORMAT, "version": VERSION, "method": method, "scene": scene,
                "config": json.dumps(dataclasses.asdict(model.cfg))}
    return _atomic_save(tensors, metadata, path)


def _read_whole(artifact: Path, method: str) -> tuple[dict[str, Tensor], dict[str, Any]]:
    """(state dict, config fields) of a whole-model artifact ``method`` wrote."""
    tensors, metadata = _read(artifact, method)
    return tensors, json.loads(metadata["config"])


def load_semantic_nerf(artifact: Path, map_location: str = "cpu") -> SemanticNeRF:
    """The Semantic-NeRF of one scene (eval mode) rebuilt from its artifact."""
    tensors, fields = _read_whole(artifact, "semantic-nerf")
    if "density_activation" in fields:
        raise outdated(f"{artifact}: this Semantic-NeRF artifact", "1 (with density_activation)", "2")
    model = SemanticNeRF(SemanticNeRFConfig(**{**fields, "scene_center": tuple(fields["scene_center"])}))
    model.load_state_dict(tensors)
    return model.to(map_location).eval()


def load_segmenter_artifact(artifact: Path, map_location: str = "cpu") -> Segmenter:
    """The finetuned 2D segmenter of one scene (eval mode) rebuilt from its ``2d-transfer`` artifact."""
    tensors, fields = _read_whole(artifact, "2d-transfer")
    model = Segmenter(SegmenterConfig(**{**fields, "class_weights": tuple(fields["class_weights"])}))
    model.load_state_dict(tensors)
    return model.to(map_location).eval()
