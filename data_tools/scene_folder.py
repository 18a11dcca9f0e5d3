"""The scene folder: sray's on-disk scene layout (what ``sray data synth`` and ``sray data convert`` write).

::

    DATASET/
      dataset.json                 {"format": "sray-scenes", "version": 1, "scenes": [names]}
      SCENE/
        scene.json                 SceneMeta.to_json() plus "image_size": [H, W]
        cameras.json               {view_id: {"K": 3x3, "c2w": 4x4}}   (OpenCV axes, metres)
        rgb/<view_id>.png          8-bit RGB
        depth/<view_id>.png        16-bit, millimetres, 0 = unknown
        label/<view_id>.png        16-bit class ids, IGNORE_ID = unlabelled

Every file is written atomically (``atomic.py``), images through the lossless codecs of ``png.py``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sray.data_tools.atomic import atomic_write_bytes, atomic_write_json
from sray.data_tools.png import decode_png, depth_to_png16, encode_png, png16_to_depth
from sray.data_tools.scene import Scene, SceneMeta, View

FORMAT = "sray-scenes"
VERSION = 1


def write_scene(scene: Scene, dataset_dir: Path) -> Path:
    """Write a scene in sray layout under ``dataset_dir/<name>``; scene.json is written last."""
    root = Path(dataset_dir) / scene.meta.name
    cameras: dict[str, dict] = {}
    hw = None
    for view in scene.views():
        hw = view.hw
        atomic_write_bytes(root / "rgb" / f"{view.view_id}.png", encode_png(view.rgb))
        atomic_write_bytes(root / "depth" / f"{view.view_id}.png", encode_png(depth_to_png16(view.depth)))
        atomic_write_bytes(root / "label" / f"{view.view_id}.png", encode_png(view.label.astype(np.uint16)))
        cameras[view.view_id] = {"K": np.asarray(view.K).tolist(), "c2w": np.asarray(view.c2w).tolist()}
    atomic_write_json(root / "cameras.json", cameras)
    atomic_write_json(root / "scene.json", {**scene.meta.to_json(), "image_size": list(hw or (0, 0))})
    return root


def write_dataset_index(dataset_dir: Path, scene_names: list[str]) -> None:
    """Write ``dataset.json`` listing the scenes (after the scenes themselves are complete)."""
    atomic_write_json(Path(dataset_dir) / "dataset.json",
                      {"format": FORMAT, "version": VERSION, "scenes": sorted(scene_names)})


def read_scene(scene_dir: Path) -> Scene:
    """Open a scene in sray layout; views are read lazily. Errors name the file and the field."""
    root = Path(scene_dir)
    meta_path, cam_path = root / "scene.json", root / "cameras.json"
    try:
        meta = SceneMeta.from_json(json.loads(meta_path.read_text()))
    except FileNotFoundError:
        raise FileNotFoundError(f"{meta_path}: missing; is {root} a scene written by "
                                "`sray data synth/convert`?") from None
    except KeyError as e:
        raise ValueError(f"{meta_path}: field {e.args[0]!r} is missing") from None
    try:
        cameras = json.loads(cam_path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"{cam_path}: missing; re-run the conversion for this scene") from None

    def read_view(view_id: str) -> View:
        def png(sub: str) -> np.ndarray:
            path = root / sub / f"{view_id}.png"
            try:
                return decode_png(path.read_bytes(), str(path))
            except FileNotFoundError:
                raise FileNotFoundError(f"{path}: missing file for view {view_id!r}") from None

        if view_id not in cameras:
            raise KeyError(f"{cam_path}: no entry for view {view_id!r}")
        cam = cameras[view_id]
        return View(view_id=view_id, rgb=png("rgb"), depth=png16_to_depth(png("depth")),
                    label=png("label").astype(np.uint16),
                    K=np.asarray(cam["K"], np.float64), c2w=np.asarray(cam["c2w"], np.float64))

    return Scene(meta=meta, read_view=read_view)


def list_scenes(dataset_dir: Path) -> list[Path]:
    """Scene folders of a dataset: those in dataset.json, else every sub-folder with a scene.json."""
    root = Path(dataset_dir)
    index = root / "dataset.json"
    if index.exists():
        return [root / name for name in json.loads(index.read_text())["scenes"]]
    return sorted(p.parent for p in root.glob("*/scene.json"))
