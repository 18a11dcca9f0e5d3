"""``sray data convert``: one source scene (any format of ``readers/registry.py``) -> one scene in sray layout.
Splits, bounds and publication (staging folder, ``check_scene``, rename, ``dataset.json``): docs/data.md."""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sray.data_tools.atomic import atomic_write_json, replace_dir
from sray.data_tools.check.scenes import check_scene
from sray.data_tools.readers.registry import get_reader
from sray.data_tools.scene import Scene, View, scene_depth_bounds
from sray.data_tools.scene_folder import list_scenes, write_dataset_index, write_scene
from sray.data_tools.splits import protocol_splits, train_splits


@dataclass
class ConvertConfig:
    """What ``sray data convert`` converts, and how."""

    format: str
    """Source format: a name in ``readers/registry.py``."""
    src: Path
    """The source scan / sequence folder."""
    out: Path
    """Dataset folder (sray layout) that receives the scene."""
    name: str | None = None
    """Scene name; default: the source folder's name (``<parent>_<name>`` for Replica ``Sequence_<n>`` folders)."""
    role: str = "train"
    """``train`` (pretraining scene) or ``test`` (unseen scene, 20-view protocol)."""
    label_space: str = "scannet20"
    """Target label space: a name in ``label_spaces.LABEL_SPACES`` (``scannet20``, ``nyu40``)."""
    size_hw: tuple[int, int] | None = None
    """Output (H, W); None = the reader's default (its registry entry)."""
    frame_skip: int | None = None
    """Keep every n-th usable frame; None = the reader's default (its registry entry)."""
    depth_scale: float = 1000.0
    """Source depth PNG units per metre (1000 = millimetres, as both layouts store)."""
    options: dict[str, object] = field(default_factory=dict)
    """Reader-specific side inputs by option name (``tsv``, ``classes``, ``scale``); files left out are searched."""
    holdout_every: int = 20
    """Train scenes: hold out every n-th view as ``test`` (0 = none)."""
    window_start: int | None = None
    """Test scenes: first view of the 20-view window; None = centred in the capture."""
    overwrite: bool = False
    """Replace an existing scene of the same name."""


@dataclass
class ConvertReport:
    """What a conversion produced: the published scene folder, views written and per split, the measured near/far
    bounds (m), and the source frames left out with the reason (invalid pose, missing file)."""

    scene_dir: Path
    n_views: int
    splits: dict[str, int]
    near: float
    far: float
    dropped_frames: dict[str, str] = field(default_factory=dict)


def default_name(src: Path) -> str:
    """Scene name from the source folder: ``room_0/Sequence_1`` -> ``room_0_Sequence_1``; dots -> '_'."""
    src = Path(src).resolve()
    name = f"{src.parent.name}_{src.name}" if re.fullmatch(r"Sequence_\d+", src.name) else src.name
    return name.replace(".", "_")


def _open_source(cfg: ConvertConfig, name: str) -> Scene:
    """Open ``cfg.src`` with the registered reader of ``cfg.format``, filling in that reader's defaults."""
    reader = get_reader(cfg.format)
    unknown = sorted(set(cfg.options) - {o.name for o in reader.options})
    if unknown:
        raise ValueError(f"options {unknown} are not inputs of the {reader.name} reader; it takes "
                         f"{[o.name for o in reader.options]}")
    return reader.load()(cfg.src, name=name, label_space=cfg.label_space, depth_scale=cfg.depth_scale, **cfg.options,
                         size_hw=cfg.size_hw or reader.size_hw, frame_skip=cfg.frame_skip or reader.frame_skip)


def convert_scene(cfg: ConvertConfig, on_view: Callable[[int], None] | None = None) -> ConvertReport:
    """Convert one source scene into ``cfg.out`` (module doc); ``on_view(n_views)`` is called after each view."""
    name = cfg.name or default_name(cfg.src)
    if not name or "." in name or "/" in name or name.startswith("-"):
        raise ValueError(f"scene name {name!r} must be non-empty, without '.' or '/'; pass --name")
    if cfg.role not in ("train", "test"):
        raise ValueError(f"role must be 'train' or 'test', got {cfg.role!r}")
    out, target = Path(cfg.out), Path(cfg.out) / name
    if target.exists() and not cfg.overwrite:
        raise FileExistsError(f"{target}: a scene of that name exists; pass --overwrite or another --name")
    scene = _open_source(cfg, name)
    meta = scene.meta
    if cfg.role == "test":
        meta.view_ids, meta.splits = protocol_splits(meta.view_ids, cfg.window_start)
    else:
        meta.splits = train_splits(meta.view_ids, cfg.holdout_every)
    meta.role = cfg.role

    depths: dict[str, np.ndarray] = {}

    def recording_read(view_id: str) -> View:
        view = scene.read_view(view_id)
        depths[view_id] = view.depth[::2, ::2].copy()  # a quarter of the pixels is plenty for percentiles
        if on_view is not None:
            on_view(len(meta.view_ids))
        return view

    staging = out / f".{name}.partial-{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    try:
        write_scene(Scene(meta=meta, read_view=recording_read), staging)
        if not 0 < meta.near < meta.far:  # a capture without depth maps brings bounds from its 3D points
            try:
                meta.near, meta.far = scene_depth_bounds(meta, depths.__getitem__)
            except ValueError as e:
                raise ValueError(f"{cfg.src}: {e}; check the depth images and --depth-scale") from None
        meta_path = staging / name / "scene.json"
        atomic_write_json(meta_path, {**json.loads(meta_path.read_text()), "near": meta.near, "far": meta.far})
        problems = check_scene(staging / name)
        if problems:
            raise ValueError("the converted scene fails `sray data check`, so nothing was written:\n" +
                             "\n".join(f"  {Path(p.file).name}: {p.what} (fix: {p.fix})" for p in problems))
        replace_dir(staging / name, target, target.with_name(f".{target.name}.old-{os.getpid()}"))
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    others = {p.name for p in list_scenes(out) if not p.name.startswith(".")}
    write_dataset_index(out, sorted(others | {name}))
    return ConvertReport(target, len(meta.view_ids), {k: len(v) for k, v in meta.splits.items()}, meta.near,
                         meta.far, dict(meta.extra.get("dropped_frames", {})))
