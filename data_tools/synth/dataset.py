"""Procedural indoor scenes: :func:`generate_scene` builds a room, walks a handheld-style camera path through it and
renders every view (RGB, z-depth, ScanNet-20 labels); :func:`generate_dataset` writes train and unseen test scenes in
sray layout, skipping scenes already written with the same parameters. Splits: ``data_tools/splits.py``."""

from __future__ import annotations

import json
import math
import multiprocessing
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sray.data_tools.label_spaces import SCANNET20
from sray.data_tools.scene import Scene, SceneMeta, View, scene_depth_bounds
from sray.data_tools.scene_folder import write_dataset_index, write_scene
from sray.data_tools.splits import PROTOCOL_WINDOW, protocol_splits, train_splits
from sray.data_tools.synth import domains
from sray.data_tools.synth.render import RenderScene, render_view
from sray.data_tools.synth.rooms import ROOM_TYPES, Room, build_room
from sray.data_tools.synth.trajectory import scan_path

GENERATOR = "sray-synth"
"""Value of ``extra["generator"]`` in every procedural scene."""
GENERATOR_VERSION = 4
"""Bumped whenever the same parameters would write different files (pixels or metadata)."""
HFOV_DEG = 62.0
"""Horizontal field of view (ScanNet's colour camera is about 58 degrees, its depth camera 58-60)."""


def intrinsics(height: int, width: int, hfov_deg: float = HFOV_DEG) -> np.ndarray:
    """float64 (3, 3) pinhole K with square pixels and the principal point at ((W-1)/2, (H-1)/2)."""
    f = width / (2.0 * math.tan(math.radians(hfov_deg) / 2.0))
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


@dataclass
class ScenePlan:
    """Everything about a procedural scene except its pixels."""

    room: Room
    render_scene: RenderScene
    poses: np.ndarray
    """float64 (n_views, 4, 4) camera-to-world, OpenCV axes."""


def plan_scene(seed: int, n_views: int, room_type: str | None = None, split: str = "in-distribution",
               randomise: float = 0.0) -> ScenePlan:
    """Room and camera path of a scene (deterministic in ``seed``), drawn from the region of ``split`` with appearance
    randomisation of strength ``randomise`` (:mod:`~sray.data_tools.synth.domains`); retries cluttered rooms."""
    rng = np.random.default_rng(seed)
    kind = room_type if room_type is not None else ROOM_TYPES[int(rng.integers(len(ROOM_TYPES)))]
    with domains.drawing(domains.domain_of(split, randomise)):
        for _ in range(10):
            room, exposure = build_room(rng, kind), domains.exposure(rng)
            k, gamma, noise = domains.sensor(rng)
            prepared = RenderScene.prepare(room, exposure=exposure, tone=(k, gamma), noise_sigma=noise, noise_seed=seed,
                                           tint=domains.room_tint(rng), randomise=randomise)
            try:
                return ScenePlan(room, prepared, scan_path(rng, room.size, prepared.boxes, n_views))
            except RuntimeError:
                continue
    raise RuntimeError(f"seed {seed}: no {kind} room with a free camera path after 10 rooms")


def split_views(view_ids: list[str], role: str, seed: int) -> dict[str, list[str]]:
    """The scene's splits for its role (``data_tools/splits.py``); a test scene's window starts at a seeded offset."""
    if role == "train":
        return train_splits(view_ids)
    if role == "test":
        if len(view_ids) < PROTOCOL_WINDOW:
            raise ValueError(f"a test scene needs at least {PROTOCOL_WINDOW} views for the source/finetune/test "
                             f"protocol, got n_views={len(view_ids)}; pass --views {PROTOCOL_WINDOW} or more")
        start = int(np.random.default_rng([seed, 20]).integers(0, len(view_ids) - PROTOCOL_WINDOW + 1))
        return protocol_splits(view_ids, start)[1]
    raise ValueError(f"role must be 'train' or 'test', got {role!r}")


def scene_params(seed: int, n_views: int, height: int, width: int, role: str, room_type: str,
                 split: str = "in-distribution", randomise: float = 0.0) -> dict:
    """The parameters that fully determine a scene's files (stored in ``extra``, compared on rerun)."""
    return {"generator": GENERATOR, "generator_version": GENERATOR_VERSION, "seed": int(seed),
            "n_views": int(n_views), "height": int(height), "width": int(width), "role": role,
            "room_type": room_type, "hfov_deg": HFOV_DEG, "split": split, "randomise": float(randomise)}


def generate_scene(name: str, seed: int, n_views: int, height: int, width: int, role: str,
                   room_type: str | None = None, on_view: Callable[[], None] | None = None,
                   split: str = "in-distribution", randomise: float = 0.0) -> Scene:
    """Render a procedural scene in memory (same arguments, identical arrays): ``room_type`` in ``ROOM_TYPES`` (None:
    from the seed), ``on_view`` after each view, ``split`` in ``domains.SPLITS``, ``randomise`` 0 = off."""
    if role == "train" and split != "in-distribution":
        raise ValueError(f"a training scene is always drawn in-distribution, got split {split!r}")
    if height < 8 or width < 8:
        raise ValueError(f"image size {height}x{width} is too small; use at least 8x8")
    split_views([f"{i:05d}" for i in range(n_views)], role, seed)  # validates role and view count early
    plan = plan_scene(seed, n_views, room_type, split, randomise)
    K = intrinsics(height, width)
    views = []
    for i, c2w in enumerate(plan.poses):
        views.append(View(f"{i:05d}", *render_view(plan.render_scene, K, c2w, (height, width), view_index=i),
                          K=K.copy(), c2w=c2w))
        if on_view is not None:
            on_view()
    view_ids = [v.view_id for v in views]
    extra = {**scene_params(seed, n_views, height, width, role, plan.room.room_type, split, randomise),
             "room_size_m": [float(v) for v in plan.room.size], "n_boxes": len(plan.room.boxes),
             "ceiling_label": "ignore (ScanNet-20 has no ceiling class)"}
    meta = SceneMeta(name=name, label_space="scannet20", class_names=list(SCANNET20), view_ids=view_ids,
                     splits=split_views(view_ids, role, seed), role=role, extra=extra)
    scene = Scene.in_memory(meta, views)
    meta.near, meta.far = scene_depth_bounds(meta, lambda v: scene.read_view(v).depth)
    return scene


def scene_name(role: str, index: int) -> str:
    """Folder and scene name of the ``index``-th scene of a role: ``synth_train_000``, ``synth_test_000``, ..."""
    return f"synth_{role}_{index:03d}"


def scene_seed(seed: int, role: str, index: int, split: str = "in-distribution") -> int:
    """Independent per-scene seed derived from the dataset seed (recorded as ``extra["seed"]`` of the scene): one
    stream for training rooms and one per test split, so no validation or shifted room repeats another room."""
    stream = 0 if role == "train" else 1 + domains.SPLITS.index(split)
    return int(np.random.SeedSequence([seed, stream, index]).generate_state(1)[0])


def _is_current(scene_dir: Path, params: dict) -> bool:
    """Whether ``scene_dir`` holds a complete scene written with exactly these parameters."""
    try:
        extra = json.loads((scene_dir / "scene.json").read_text()).get("extra", {})
    except (FileNotFoundError, json.JSONDecodeError):
        return False
    return all(extra.get(k) == v for k, v in params.items())


def _prune_stale_views(scene_dir: Path, view_ids: list[str]) -> None:
    """Remove view images of an earlier, larger run of the same scene name."""
    keep = {f"{v}.png" for v in view_ids}
    for sub in ("rgb", "depth", "label"):
        for path in (scene_dir / sub).glob("*.png"):
            if path.name not in keep:
                path.unlink()


def _write_scene(out: Path, name: str, own_seed: int, n_views: int, height: int, width: int, role: str,
                 room_type: str, split: str, randomise: float, on_view: Callable[[], None] | None = None) -> None:
    """Generate one scene and write it under ``out`` (scene.json last)."""
    scene = generate_scene(name, own_seed, n_views, height, width, role, room_type, on_view=on_view, split=split,
                           randomise=randomise)
    (out / name / "scene.json").unlink(missing_ok=True)
    write_scene(scene, out)
    _prune_stale_views(out / name, scene.meta.view_ids)


def generate_dataset(out: Path, n_train: int, n_test: int, n_views: int, height: int, width: int, seed: int,
                     progress: bool = True, workers: int = 1, split: str = "in-distribution",
                     randomise: float = 0.0) -> list[Path]:
    """Write ``n_train`` train and ``n_test`` test scenes (from ``split``) under ``out``; returns scene dirs.
    ``randomise`` applies to training scenes only (worlds with and without it share test rooms); room types cycle from a
    seeded offset (a small dataset covers all); a scene whose scene.json (written last) records the same parameters is
    skipped; ``workers`` > 1 renders in spawned processes (same files)."""
    if n_train < 0 or n_test < 0 or n_train + n_test == 0:
        raise ValueError(f"need at least one scene, got n_train={n_train}, n_test={n_test}")
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    domains.domain_of(split)
    domains.domain_of("in-distribution", randomise)
    out = Path(out)
    jobs = [("train", i) for i in range(n_train)] + [("test", i) for i in range(n_test)]
    offset = seed % len(ROOM_TYPES)
    bar = tqdm(total=len(jobs) * n_views, unit="view", desc="sray data synth", disable=not progress)
    written: list[Path] = []
    todo: list[tuple] = []
    for k, (role, i) in enumerate(jobs):
        name = scene_name(role, i)
        own_split, own_random = (split, 0.0) if role == "test" else ("in-distribution", randomise)
        own_seed, room_type = scene_seed(seed, role, i, own_split), ROOM_TYPES[(offset + k) % len(ROOM_TYPES)]
        written.append(out / name)
        if _is_current(out / name, scene_params(own_seed, n_views, height, width, role, room_type, own_split,
                                                own_random)):
            bar.update(n_views)
        else:
            todo.append((out, name, own_seed, n_views, height, width, role, room_type, own_split, own_random))
    if workers == 1:
        for args in todo:
            bar.set_postfix_str(f"{args[1]} ({args[7]})")
            _write_scene(*args, on_view=lambda: bar.update(1))
    else:
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            for future in [pool.submit(_write_scene, *args) for args in todo]:
                future.result()
                bar.update(n_views)
    bar.close()
    write_dataset_index(out, [p.name for p in written])
    return written
