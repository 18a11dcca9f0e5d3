"""The S-Ray model a fly-through renders: a shared checkpoint's, or one scene's finetuned model from a fleet."""

from __future__ import annotations

from pathlib import Path

from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.folders import resolve_checkpoint
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.finetune.methods.sray_method import METHOD
from sray.platform.finetune.scene_artifacts import load_scene_model, read_sray_delta


def artifact_file(artifact: Path) -> Path:
    """The delta file of ``artifact``: the file itself, or the delta in a fleet's ``scenes/<scene>/sray`` folder."""
    artifact = Path(artifact)
    return artifact / METHOD.artifact_file if artifact.is_dir() else artifact


def render_model(checkpoint: Path, artifact: Path | None, scene: str) -> tuple[SRayModel, dict[str, str]]:
    """The model (eval mode, CPU) and what made it; ``artifact``: a scene's S-Ray delta, None for the shared model."""
    folder = resolve_checkpoint(checkpoint)
    if artifact is None:
        return model_from_checkpoint(folder)[0], {"checkpoint": str(folder)}
    file = artifact_file(artifact).resolve()
    _, metadata = read_sray_delta(file)
    if metadata.get("scene") != scene:
        raise ValueError(f"{file}: field 'scene' is {metadata.get('scene')!r}, but the render is of scene {scene!r}; "
                         f"pass that scene's artifact (<fleet>/scenes/{scene}/{METHOD.name}/)")
    return load_scene_model(folder, file), {"checkpoint": str(folder), "artifact": str(file)}
