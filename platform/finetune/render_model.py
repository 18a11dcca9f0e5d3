"""The S-Ray model a fly-through renders: a shared checkpoint's, or one scene's finetuned model from a fleet.

A fleet stores a scene's S-Ray finetune as a delta on the shared checkpoint (``scene_artifacts.py``); it is
applied here as the fleet applies it (:func:`~sray.platform.finetune.scene_artifacts.load_scene_model`, which
refuses a delta made from another checkpoint). A delta finetuned on another scene is refused too.
"""

from __future__ import annotations

from pathlib import Path

from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.folders import resolve_checkpoint
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.finetune.methods.sray_method import METHOD
from sray.platform.finetune.scene_artifacts import load_scene_model, read_sray_delta


def artifact_file(artifact: Path) -> Path:
    """The delta file of ``artifact``: the file itself, or ``<folder>/sray_delta.safetensors`` for a fleet's
    ``scenes/<scene>/sray`` folder."""
    artifact = Path(artifact)
    return artifact / METHOD.artifact_file if artifact.is_dir() else artifact


def render_model(checkpoint: Path, artifact: Path | None, scene: str) -> tuple[SRayModel, dict[str, str]]:
    """The model (eval mode, CPU) and what made it (``{"checkpoint", "artifact"?}``, absolute paths).

    ``checkpoint``: a checkpoint folder, a job's ``checkpoints/`` folder or a job folder (``resolve_checkpoint``);
    ``artifact``: None for the shared model, else a scene's S-Ray delta (file or folder) finetuned from that
    checkpoint on ``scene``. ValueError / FileNotFoundError (one line, naming the file and field) otherwise.
    """
    folder = resolve_checkpoint(checkpoint)
    if artifact is None:
        return model_from_checkpoint(folder)[0], {"checkpoint": str(folder)}
    file = artifact_file(artifact).resolve()
    _, metadata = read_sray_delta(file)
    if metadata.get("scene") != scene:
        raise ValueError(f"{file}: field 'scene' is {metadata.get('scene')!r}, but the render is of scene {scene!r}; "
                         f"pass that scene's artifact (<fleet>/scenes/{scene}/{METHOD.name}/)")
    return load_scene_model(folder, file), {"checkpoint": str(folder), "artifact": str(file)}
