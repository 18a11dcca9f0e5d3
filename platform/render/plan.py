"""What a fly-through will show, decided and checked before anything is rendered or written.

:func:`plan_flythrough` reads the scene's views from its shards and builds the camera path: the spline
through the scene's own source and finetune cameras in capture order (``scene.source_pool``: ``train``
minus ``test`` for a train scene), the orbit around them, or a nerfstudio ``camera_path.json``. Built paths
use the intrinsics of the scene's first pool view scaled to the asked size (``scale_intrinsics``, the
pixel-centre rule). Every bad input is a one-line ValueError (or FileNotFoundError) naming the file and field.
"""

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

BUILT_PATHS = ("spline", "orbit")
"""Paths built from the scene's own cameras (``--path``)."""
DEFAULT_FPS = 15.0
"""Frames per second of a video when neither the request nor the camera-path file sets it."""


@dataclass(frozen=True)
class FlythroughPlan:
    """A checked fly-through request: the scene, its stored views and the cameras to render."""

    shards: Path
    """Shard folder (``manifest.json``)."""
    manifest: Manifest
    """The shard folder's manifest (its neighbour rule names the source rule)."""
    meta: SceneMeta
    """The scene's metadata (splits, class names, near/far)."""
    views: dict[str, StoredView]
    """The scene's stored views by id (encoded; decoded only where used)."""
    path: CameraPath
    """One camera per frame."""
    fps: float
    """Frames per second of the videos."""


def scene_meta(shards: Path, scene: str) -> tuple[Manifest, SceneMeta]:
    """The manifest and the metadata of ``scene``; ValueError naming the manifest when it has no such scene."""
    manifest = read_manifest(Path(shards))
    if scene not in manifest.scenes:
        raise ValueError(f"{Path(shards) / 'manifest.json'}: field 'scenes' has no scene {scene!r}; known: "
                         f"{', '.join(sorted(manifest.scenes)[:10])}")
    return manifest, SceneMeta.from_json(manifest.scenes[scene].meta)


def built_path(kind: str, views: dict[str, StoredView], meta: SceneMeta, image_hw: tuple[int, int],
               n_frames: int, size_hw: tuple[int, int]) -> CameraPath:
    """The ``kind`` path (:data:`BUILT_PATHS`) of ``n_frames`` frames at ``size_hw`` through or around the scene's
    pool cameras (views stored at ``image_hw``)."""
    keys = source_pool(meta)
    c2ws = np.stack([views[v].c2w for v in keys])
    if kind == "spline":
        poses, what = spline_path(c2ws, n_frames), f"spline through {len(keys)} cameras"
    elif kind == "orbit":
        poses, what = orbit_path(c2ws, n_frames), f"orbit around {len(keys)} cameras"
    else:
        raise ValueError(f"path {kind!r}: use one of {', '.join(BUILT_PATHS)} or a camera-path file")
    K = scale_intrinsics(views[keys[0]].K, image_hw, size_hw)
    return CameraPath(c2w=poses, K=np.repeat(K[None], n_frames, axis=0), hw=size_hw, describe=what)


def plan_flythrough(shards: Path, scene: str, *, path: str = "spline", camera_path: Path | None = None,
                    n_frames: int = 60, size_hw: tuple[int, int] | None = None,
                    fps: float | None = None) -> FlythroughPlan:
    """Check the request and build its cameras (module doc); reads the scene's views, writes nothing.

    ``camera_path``: a nerfstudio camera_path.json (its frames, size and fps; ``size_hw`` and ``fps`` override
    them), else a built ``path`` of ``n_frames`` frames at ``size_hw`` (default: the scene's image size).
    """
    if camera_path is None and n_frames < 1:
        raise ValueError(f"frames is {n_frames}; a fly-through needs at least 1 frame")
    if size_hw is not None and min(size_hw) < 1:
        raise ValueError(f"size is {size_hw[1]}x{size_hw[0]}; width and height must be positive")
    if fps is not None and fps <= 0:
        raise ValueError(f"fps is {fps}; it must be positive")
    manifest, meta = scene_meta(shards, scene)
    file_fps = None
    if camera_path is not None:
        cameras, file_fps = read_camera_path(Path(camera_path), size_hw)
    views = read_scene_views(Path(shards), manifest.scenes[scene])
    if camera_path is None:
        image_hw = (int(manifest.scenes[scene].image_size[0]), int(manifest.scenes[scene].image_size[1]))
        cameras = built_path(path, views, meta, image_hw, n_frames, size_hw or image_hw)
    return FlythroughPlan(shards=Path(shards), manifest=manifest, meta=meta, views=views, path=cameras,
                          fps=fps or file_fps or DEFAULT_FPS)
