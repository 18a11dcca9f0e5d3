"""``sray data check``: list every :class:`Problem` of a dataset folder (:func:`check_dataset`), a scene folder
(:func:`check_scene`) or an in-memory :class:`Scene` (:func:`check_scene_object`), reading only; no problem means
the data is fit for ``sray data shard``. A scene marked ``"labelled": false`` passes with ignore-only label images."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sray.data_tools.check.rules import (RECONVERT, CheckLimits, Problem, intrinsics_problems, label_problems,
                                         meta_problems, pose_problems)
from sray.data_tools.png import decode_png
from sray.data_tools.scene import Scene
from sray.data_tools.scene_folder import FORMAT, VERSION


def _read_json(path: Path, out: list[Problem]) -> object | None:
    """Parsed JSON of ``path``, or None after recording why it cannot be read."""
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        out.append(Problem(str(path), "file is missing", RECONVERT))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        out.append(Problem(str(path), f"not readable JSON ({e})", RECONVERT))
    return None


def _read_png(path: Path, kind: str, out: list[Problem]) -> np.ndarray | None:
    """Decoded PNG of ``path`` checked for the dtype/channels of ``kind`` (rgb, depth, label)."""
    fix = f"rewrite {path.name}; {RECONVERT}"
    try:
        image = decode_png(path.read_bytes(), str(path))
    except FileNotFoundError:
        out.append(Problem(str(path), f"{kind} image is missing", fix))
        return None
    except (OSError, ValueError):
        out.append(Problem(str(path), f"{kind} image is not a readable PNG", fix))
        return None
    expected = {"rgb": ((np.uint8,), 3, "8-bit RGB"), "depth": ((np.uint16,), 2, "16-bit single-channel (mm)"),
                "label": ((np.uint8, np.uint16), 2, "8/16-bit single-channel")}[kind]
    if image.dtype not in expected[0] or image.ndim != expected[1]:
        out.append(Problem(str(path), f"{kind} image is {image.dtype} with shape {image.shape}, "
                                      f"expected {expected[2]}", fix))
        return None
    return image


def _size_problem(path: Path, kind: str, got: tuple[int, int], want: tuple[int, int], ref: str) -> Problem:
    return Problem(str(path), f"{kind} image is {got[1]}x{got[0]} but {ref} is {want[1]}x{want[0]}",
                   f"store every image of a view at the same size; {RECONVERT}")


def check_scene(scene_dir: Path, limits: CheckLimits | None = None) -> list[Problem]:
    """Every problem of one scene folder in sray layout."""
    limits = limits or CheckLimits()
    root = Path(scene_dir)
    out: list[Problem] = []
    meta_path, cam_path = root / "scene.json", root / "cameras.json"
    meta = _read_json(meta_path, out)
    if meta is None:
        return out
    if not isinstance(meta, dict):
        return [Problem(str(meta_path), "top level must be a JSON object", RECONVERT)]
    out += meta_problems(meta, str(meta_path), root.name, limits)
    views = meta.get("view_ids")
    views = [v for v in views if isinstance(v, str)] if isinstance(views, list) else []
    size = meta.get("image_size")
    valid_size = isinstance(size, list) and len(size) == 2 and all(isinstance(s, int) for s in size)
    meta_hw = tuple(size) if valid_size else None
    classes = meta.get("class_names")
    n_classes = len(classes) if isinstance(classes, list) else None
    ignore_id = meta.get("ignore_id", 255)
    cameras = _read_json(cam_path, out)
    if cameras is not None and not isinstance(cameras, dict):
        out.append(Problem(str(cam_path), "top level must be a JSON object {view_id: {K, c2w}}", RECONVERT))
        cameras = None
    for view in views:
        rgb_path, depth_path, label_path = (root / sub / f"{view}.png" for sub in ("rgb", "depth", "label"))
        rgb = _read_png(rgb_path, "rgb", out)
        hw = rgb.shape[:2] if rgb is not None else meta_hw
        if rgb is not None and meta_hw is not None and rgb.shape[:2] != meta_hw:
            out.append(_size_problem(rgb_path, "rgb", rgb.shape[:2], meta_hw, "scene.json image_size"))
        for path, kind in ((depth_path, "depth"), (label_path, "label")):
            image = _read_png(path, kind, out)
            if image is None:
                continue
            if hw is not None and image.shape[:2] != hw:
                ref = "the rgb image" if rgb is not None else "scene.json image_size"
                out.append(_size_problem(path, kind, image.shape[:2], hw, ref))
            if kind == "label" and n_classes and isinstance(ignore_id, int):
                out += label_problems(image, n_classes, ignore_id, str(path))
                if meta.get("labelled") is False and (image != ignore_id).any():
                    out.append(Problem(str(path), f"scene.json says 'labelled': false, but this label image holds "
                                                  f"ids other than the ignore id {ignore_id}",
                                       "set 'labelled' to true, or store the ignore id everywhere"))
        if cameras is None:
            continue
        cam = cameras.get(view)
        if not isinstance(cam, dict) or "K" not in cam or "c2w" not in cam:
            out.append(Problem(str(cam_path), f"no K and c2w for view {view!r}", RECONVERT))
            continue
        out += intrinsics_problems(cam["K"], hw, str(cam_path), view, limits.max_centre_offset)
        out += pose_problems(cam["c2w"], str(cam_path), view, limits.pose_tol)
    return out


def check_dataset(path: Path, limits: CheckLimits | None = None) -> list[Problem]:
    """Every problem of a dataset folder in sray layout (or of one scene folder)."""
    root = Path(path)
    if not root.is_dir():
        return [Problem(str(root), "not a folder", "pass a dataset folder written by `sray data synth/convert`")]
    if (root / "scene.json").exists():
        return check_scene(root, limits)
    out: list[Problem] = []
    index_path = root / "dataset.json"
    # visible sub-folders holding a scene.json (hidden ones are a converter's unfinished work)
    on_disk = {p.parent.name for p in root.glob("*/scene.json") if not p.parent.name.startswith(".")}
    names = sorted(on_disk)
    if index_path.exists():
        index = _read_json(index_path, out)
        fix = "rewrite it with scene_folder.write_dataset_index (any `sray data convert` into this folder does)"
        if isinstance(index, dict) and isinstance(index.get("scenes"), list):
            if index.get("format") != FORMAT or index.get("version") != VERSION:
                out.append(Problem(str(index_path), f"format/version is {index.get('format')!r}/"
                                   f"{index.get('version')!r}, expected {FORMAT!r}/{VERSION}", fix))
            names = [n for n in index["scenes"] if isinstance(n, str)]
            for name in sorted(set(names) - on_disk):
                out.append(Problem(str(index_path), f"lists scene {name!r}, but {root / name}/scene.json does "
                                   "not exist", "convert that scene again or drop it from the list"))
            for name in sorted(on_disk - set(names)):
                out.append(Problem(str(index_path), f"does not list scene folder {name!r} (it would be ignored)",
                                   "add it to 'scenes' or remove the folder"))
            names = [n for n in names if n in on_disk]
        elif index is not None:
            out.append(Problem(str(index_path), "must be a JSON object with a 'scenes' list", fix))
    if not names and not out:
        out.append(Problem(str(root), "no scenes found (no <scene>/scene.json)",
                           "point at a folder written by `sray data synth` or `sray data convert`"))
    for name in names:
        out += check_scene(root / name, limits)
    return out


def check_scene_object(scene: Scene, limits: CheckLimits | None = None) -> list[Problem]:
    """Every problem of an in-memory scene (the same rules as on disk); files are ``<scene>:<view>``."""
    limits = limits or CheckLimits()
    name = scene.meta.name
    views = list(scene.views())
    meta = {**scene.meta.to_json(), "image_size": list(views[0].hw) if views else None}
    out = meta_problems(meta, f"{name}:scene.json", name, limits)
    for view in views:
        where, hw = f"{name}:{view.view_id}", view.hw
        if view.rgb.dtype != np.uint8 or view.rgb.shape != (*hw, 3) or hw != tuple(meta["image_size"]):
            out.append(Problem(where, f"rgb must be uint8 {tuple(meta['image_size'])} x 3, got {view.rgb.dtype} "
                                      f"{view.rgb.shape}", "resize or convert the colour image"))
        if view.depth.shape != hw or not np.isfinite(view.depth).all() or (view.depth < 0).any():
            out.append(Problem(where, "depth must be finite, >= 0 and the size of rgb",
                               "store 0 for unknown depth and resample depth to the rgb camera"))
        if view.label.shape != hw:
            out.append(Problem(where, f"label shape {view.label.shape} differs from rgb {hw}", "resample labels"))
        out += label_problems(view.label, len(scene.meta.class_names), scene.meta.ignore_id, where)
        out += intrinsics_problems(view.K, hw, where, view.view_id, limits.max_centre_offset)
        out += pose_problems(view.c2w, where, view.view_id, limits.pose_tol)
    return out
