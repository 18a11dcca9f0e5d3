"""What a fly-through will show, decided and checked before anything is rendered or written. Built paths go through
or around the scene's pool cameras (``scene.source_pool``) with the first one's intrinsics scaled to the asked size."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sray.data_tools.loader.views import StoredView, read_scene_views
from sray.data_tools.readers.common import scale_intrinsics
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import Manifest, read_manifest
from sray.platform.render.camera_paths import CameraPath, orbit_path, spline_path
from sray.platform.render.nerfstudio_path import read_camera_path

BUILT_PATHS = {"spline": (spline_path, "spline through"), "orbit": (orbit_path, "orbit around")}
"""``--path`` -> (the path of n frames through key cameras, the phrase describing it)."""
DEFAULT_FPS = 15.0  # frames per second of a video when neither the request nor the camera-path file sets it


@dataclass(frozen=True)
class FlythroughPlan:
    """A checked fly-through request: shards, manifest, scene metadata, views by id (decoded if used), cameras, fps."""

    shards: Path
    manifest: Manifest
    meta: SceneMeta
    views: dict[str, StoredView]
    path: CameraPath
    fps: float


def built_path(kind: str, views: dict[str, StoredView], meta: SceneMeta, image_hw: tuple[int, int],
               n_frames: int, size_hw: tuple[int, int]) -> CameraPath:
    """``kind`` path (:data:`BUILT_PATHS`), ``n_frames`` at ``size_hw``, by pool cameras (stored at ``image_hw``)."""
    if kind not in BUILT_PATHS:
        raise ValueError(f"path {kind!r}: use one of {', '.join(BUILT_PATHS)} or a camera-path file")
    build, what = BUILT_PATHS[kind]
    keys = source_pool(meta)
    K = scale_intrinsics(views[keys[0]].K, image_hw, size_hw)
    return CameraPath(c2w=build(np.stack([views[v].c2w for v in keys]), n_frames),
                      K=np.repeat(K[None], n_frames, axis=0), hw=size_hw, describe=f"{what} {len(keys)} cameras")


def plan_flythrough(shards: Path, scene: str, *, path: str = "spline", camera_path: Path | None = None,
                    n_frames: int = 60, size_hw: tuple[int, int] | None = None,
                    fps: float | None = None) -> FlythroughPlan:
    """Check the request and build its cameras: a nerfstudio ``camera_path`` file (``size_hw`` and ``fps`` override its
    own), else a built ``path`` of ``n_frames`` at ``size_hw`` (default: the scene's); errors name file and field."""
    if camera_path is None and n_frames < 1:
        raise ValueError(f"frames is {n_frames}; a fly-through needs at least 1 frame")
    if size_hw is not None and min(size_hw) < 1:
        raise ValueError(f"size is {size_hw[1]}x{size_hw[0]}; width and height must be positive")
    if fps is not None and fps <= 0:
        raise ValueError(f"fps is {fps}; it must be positive")
    shards = Path(shards)
    manifest = read_manifest(shards)
    if scene not in manifest.scenes:
        raise ValueError(f"{shards / 'manifest.json'}: field 'scenes' has no scene {scene!r}; known: "
                         f"{', '.join(sorted(manifest.scenes)[:10])}")
    entry, meta = manifest.scenes[scene], SceneMeta.from_json(manifest.scenes[scene].meta)
    file_fps = None
    if camera_path is not None:
        cameras, file_fps = read_camera_path(Path(camera_path), size_hw)
    views = read_scene_views(shards, entry)
    if camera_path is None:
        image_hw = (int(entry.image_size[0]), int(entry.image_size[1]))
        cameras = built_path(path, views, meta, image_hw, n_frames, size_hw or image_hw)
    return FlythroughPlan(shards=shards, manifest=manifest, meta=meta, views=views, path=cameras,
                          fps=fps or file_fps or DEFAULT_FPS)
