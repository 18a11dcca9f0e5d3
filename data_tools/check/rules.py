"""The rules of ``sray data check``: pure functions from a value (a pose, intrinsics, a label map, scene.json's
fields) to :class:`Problem` records, shared by the on-disk and the in-memory check (``scenes.py``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sray.data_tools.label_spaces import LABEL_SPACES
from sray.data_tools.scene import SPLIT_NAMES

REQUIRED_FIELDS = ("name", "label_space", "class_names", "view_ids", "splits", "near", "far", "role",
                   "image_size")
"""scene.json fields a scene must carry (``ignore_id`` and ``extra`` are optional)."""

RECONVERT = "re-run `sray data convert` (or `sray data synth`) for this scene"


@dataclass(frozen=True)
class Problem:
    """One defect: the file at fault (``<scene>:<view_id>`` in memory), what is wrong (with the values), the fix."""

    file: str
    what: str
    fix: str


@dataclass
class CheckLimits:
    """Thresholds of the checker."""

    min_train_views: int = 4
    """A training scene needs at least this many ``train`` views (the loader's source views + 1 query)."""
    min_source_views: int = 2
    """A test scene needs at least this many ``source`` views."""
    min_test_views: int = 1
    """A test scene needs at least this many ``test`` views."""
    pose_tol: float = 1e-4
    """Tolerance of the rigidity checks: |R^T R - I|, |det R - 1| and the last row of c2w."""
    max_centre_offset: float = 0.2
    """Largest principal-point offset from the image centre, as a fraction of its size (beyond: K of another size)."""


def _matrix(value: object, name: str, shape: tuple[int, int], file: str, view: str,
            fix: str) -> tuple[np.ndarray | None, list[Problem]]:
    """(the float64 matrix, []) or (None, [why it is not a finite matrix of ``shape``])."""
    try:
        m = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None, [Problem(file, f"view {view!r}: {name} is not a numeric matrix", fix)]
    if m.shape != shape:
        return None, [Problem(file, f"view {view!r}: {name} has shape {m.shape}, expected {shape}", fix)]
    if not np.isfinite(m).all():
        return None, [Problem(file, f"view {view!r}: {name} has non-finite entries (inf/NaN)", fix)]
    return m, []


def pose_problems(c2w: object, file: str, view: str, tol: float) -> list[Problem]:
    """A camera-to-world must be a finite 4x4 rigid transform: R orthonormal, det +1, last row 0 0 0 1."""
    fix = f"store a rigid camera-to-world (OpenCV axes) for view {view!r}; {RECONVERT}"
    m, out = _matrix(c2w, "c2w", (4, 4), file, view, fix)
    if m is None:
        return out
    if np.abs(m[3] - [0.0, 0.0, 0.0, 1.0]).max() > tol:
        out.append(Problem(file, f"view {view!r}: c2w last row is {m[3].tolist()}, expected [0, 0, 0, 1]", fix))
    r = m[:3, :3]
    ortho = float(np.abs(r.T @ r - np.eye(3)).max())
    if ortho > tol:
        out.append(Problem(file, f"view {view!r}: c2w rotation is not orthonormal "
                                 f"(max |R^T R - I| = {ortho:.3g})", fix))
    det = float(np.linalg.det(r))
    if abs(det - 1.0) > tol and ortho <= tol:
        out.append(Problem(file, f"view {view!r}: c2w rotation has determinant {det:.3g}, expected +1 "
                                 "(a reflection: one axis is flipped)", fix))
    return out


def intrinsics_problems(K: object, hw: tuple[int, int] | None, file: str, view: str,
                        max_centre_offset: float) -> list[Problem]:
    """K must be a finite 3x3 pinhole matrix with positive focals, bottom row 0 0 1, and a principal
    point inside (and near the centre of) an image of size ``hw`` (skipped when ``hw`` is None)."""
    fix = f"store the intrinsics of the {hw[1]}x{hw[0]} images" if hw else "store valid intrinsics"
    fix += f" for view {view!r} (pixel (u, v) centred at (u, v)); {RECONVERT}"
    k, out = _matrix(K, "K", (3, 3), file, view, fix)
    if k is None:
        return out
    if not np.array_equal(k[2], [0.0, 0.0, 1.0]) or k[1, 0] != 0.0:
        out.append(Problem(file, f"view {view!r}: K is not an upper-triangular pinhole matrix with last row "
                                 f"[0, 0, 1] (rows {k[1].tolist()}, {k[2].tolist()})", fix))
    if k[0, 0] <= 0 or k[1, 1] <= 0:
        out.append(Problem(file, f"view {view!r}: focal lengths must be positive, "
                                 f"got fx={k[0, 0]:g}, fy={k[1, 1]:g}", fix))
    if hw is None:
        return out
    h, w = hw
    cx, cy = float(k[0, 2]), float(k[1, 2])
    if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
        out.append(Problem(file, f"view {view!r}: principal point ({cx:g}, {cy:g}) lies outside "
                                 f"the {w}x{h} image", fix))
    elif abs(cx - (w - 1) / 2) > max_centre_offset * w or abs(cy - (h - 1) / 2) > max_centre_offset * h:
        out.append(Problem(file, f"view {view!r}: principal point ({cx:g}, {cy:g}) is far from the centre "
                                 f"({(w - 1) / 2:g}, {(h - 1) / 2:g}) of the {w}x{h} image: intrinsics of "
                                 "another resolution?", fix))
    return out


def label_problems(label: np.ndarray, n_classes: int, ignore_id: int, file: str) -> list[Problem]:
    """Every label id must be a class id (0 .. n_classes-1) or the ignore id."""
    ids = np.unique(label)
    bad = ids[(ids >= n_classes) & (ids != ignore_id)]
    if bad.size == 0:
        return []
    return [Problem(file, f"label ids {bad[:10].tolist()}{' ...' if bad.size > 10 else ''} are outside the label "
                          f"space (0..{n_classes - 1}, ignore {ignore_id})",
                    f"map them to the scene's classes or to {ignore_id}; {RECONVERT}")]


def _is_number(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _id_list(x: object) -> bool:
    return isinstance(x, list) and all(isinstance(v, str) for v in x)


def meta_problems(meta: dict, file: str, dir_name: str, limits: CheckLimits) -> list[Problem]:
    """Fields of scene.json: presence, types, names, bounds, splits and per-role view counts."""
    out = []

    def bad(what: str, fix: str = RECONVERT) -> None:
        out.append(Problem(file, what, fix))

    for key in REQUIRED_FIELDS:
        if key not in meta:
            bad(f"field {key!r} is missing")
    name, space, classes = meta.get("name"), meta.get("label_space"), meta.get("class_names")
    if "name" in meta and (not isinstance(name, str) or name != dir_name):
        bad(f"field 'name' is {name!r} but the scene folder is {dir_name!r}", "rename the folder or the scene")
    if "label_space" in meta and not isinstance(space, str):
        bad(f"field 'label_space' must be a string, got {space!r}")
    if "class_names" in meta and (not _id_list(classes) or not classes):
        bad("field 'class_names' must be a non-empty list of strings")
    elif isinstance(space, str) and space in LABEL_SPACES and classes != LABEL_SPACES[space]:
        bad(f"field 'class_names' does not match the {space!r} label space")
    views = meta.get("view_ids")
    if "view_ids" in meta:
        if not _id_list(views) or not views:
            bad("field 'view_ids' must be a non-empty list of strings")
        else:
            dupes = sorted({v for v in views if views.count(v) > 1})
            odd = [v for v in views if not v or "." in v or "/" in v]
            if dupes:
                bad(f"field 'view_ids' repeats {dupes[:5]}")
            if odd:
                bad(f"view ids {odd[:5]} are empty or contain '.' or '/' (webdataset splits keys on dots)")
    near, far = meta.get("near"), meta.get("far")
    if "near" in meta and "far" in meta and not (_is_number(near) and _is_number(far) and 0 < near < far):
        bad(f"near/far must be finite with 0 < near < far, got near={near!r}, far={far!r}",
            "measure them from the depth with scene.scene_depth_bounds; " + RECONVERT)
    role = meta.get("role")
    if "role" in meta and role not in ("train", "test"):
        bad(f"field 'role' must be 'train' or 'test', got {role!r}")
    ignore_id = meta.get("ignore_id", 255)
    if not isinstance(ignore_id, int) or (_id_list(classes) and 0 <= ignore_id < len(classes)):
        bad(f"field 'ignore_id' {ignore_id!r} must be an integer outside the class ids")
    if not isinstance(meta.get("labelled", True), bool):
        bad(f"field 'labelled' must be true or false, got {meta.get('labelled')!r}")
    size = meta.get("image_size")
    if "image_size" in meta and not (isinstance(size, list) and len(size) == 2
                                     and all(isinstance(s, int) and s > 0 for s in size)):
        bad(f"field 'image_size' must be [H, W] with positive integers, got {size!r}")
    out += _split_problems(meta.get("splits"), views if _id_list(views) else None, role, file, limits)
    return out


def _split_problems(splits: object, views: list[str] | None, role: object, file: str,
                    limits: CheckLimits) -> list[Problem]:
    """Splits must name known split names and known views, in the numbers the role needs."""
    if splits is None:
        return []
    if not isinstance(splits, dict) or not all(_id_list(v) for v in splits.values()):
        return [Problem(file, "field 'splits' must map split names to lists of view ids", RECONVERT)]
    out = []
    for split, ids in splits.items():
        if split not in SPLIT_NAMES:
            out.append(Problem(file, f"unknown split {split!r} (known: {list(SPLIT_NAMES)})", RECONVERT))
        unknown = [v for v in ids if views is not None and v not in views]
        if unknown:
            out.append(Problem(file, f"split {split!r} references unknown views {unknown[:5]}",
                               "list only ids of 'view_ids' in the splits; " + RECONVERT))
    need = {"train": [("train", limits.min_train_views)],
            "test": [("source", limits.min_source_views), ("test", limits.min_test_views)]}
    need = need.get(role, []) if isinstance(role, str) else []
    for split, minimum in need:
        if len(splits.get(split, [])) < minimum:
            out.append(Problem(file, f"a {role} scene needs >= {minimum} {split!r} views, has "
                                     f"{len(splits.get(split, []))}",
                               "convert more frames (lower --frame-skip) or assign more views to the split"))
    if role == "test":
        leaked = sorted(set(splits.get("test", [])) & (set(splits.get("source", [])) | set(splits.get("finetune", []))))
        if leaked:
            out.append(Problem(file, f"test views {leaked[:5]} are also source/finetune views",
                               "keep held-out test views out of the source and finetune splits"))
    return out
