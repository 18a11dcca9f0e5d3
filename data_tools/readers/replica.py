"""Reader: a Replica sequence as rendered for Semantic-NeRF (``rgb/``, ``depth/``, ``semantic_class/``,
``traj_w_c.txt``: OpenCV camera-to-world rows, no axis change; fx = fy = W/2, cx = (W - 1) / 2, cy = (H - 1) / 2).
Class ids -> names by the scene's ``info_semantic.json`` -> NYU40 by :data:`REPLICA_TO_NYU40` -> label space.
Layout and rules: docs/data.md, "Replica as rendered for Semantic-NeRF"."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from sray.data_tools.label_spaces import NYU40, SCANNET20, class_names
from sray.data_tools.readers.common import (numbered_files, nyu40_to_label, read_depth_m, read_file, read_image,
                                            read_rgb8, resample_nearest, resize_rgb, scale_intrinsics, select_frames)
from sray.data_tools.scene import IGNORE_ID, Scene, SceneMeta, View

CLASS_FILE = "info_semantic.json"

_REPLICA_NAMES: dict[str | None, str] = {
    "bag": "backpack, handbag", "cabinet": "base cabinet, wall cabinet, wardrobe", "books": "book",
    "counter": "countertop", "pillow": "cushion", "night stand": "nightstand", "shelves": "shelf, rack",
    "floor mat": "rug, mat", "clothes": "cloth, clothing, set of clothing, scarf", "towel": "paper towel",
    "paper": "tissue paper", "television": "tv screen, monitor", "chair": "stool",
    "otherfurniture": "beanbag, bench, plant stand, tv stand",
    "otherstructure": "beam, pillar, pipe, panel, handrail, stair, vent, shower stall",
    "otherprop": "basket, bike, bin, blanket, comforter, bottle, bowl, camera, candle, chopping board, clock, coaster, "
                 "computer keyboard, cooktop, cup, desk organizer, desktop computer, exercise ball, faucet, "
                 "hair dryer, indoor plant, kitchen utensil, knife block, laptop, major appliance, small appliance, "
                 "microwave, mouse, pan, phone, plate, pot, remote control, sculpture, shoe, switch, table runner, "
                 "tablet, toothbrush, umbrella, utensil holder, vase, wall plug, logo",
    None: "undefined, void, other leaf, anonymize text, anonymize picture",
}
"""NYU40 class name (None: ignore) -> the normalised Replica class names mapped to it, by meaning; NYU40 names
(wall, floor, chair, ...) map to themselves and are not listed."""

REPLICA_TO_NYU40: dict[str, str | None] = {r: n for n, names in _REPLICA_NAMES.items() for r in names.split(", ")}
"""Replica class name (normalised) -> NYU40 class name or None (ignore)."""

REPLICA_TO_SCANNET20: dict[str, str | None] = {
    **{n: (n if n in SCANNET20 else None) for n in NYU40},
    **{r: (n if n in SCANNET20 else None) for r, n in REPLICA_TO_NYU40.items()},
}
"""Replica class name -> ScanNet-20 class name, or None where the class is ignored in ScanNet-20."""


def normalise_name(name: str) -> str:
    """Lower case, '-' and '_' as spaces, single spaces: ``Base-Cabinet`` -> ``base cabinet``."""
    return " ".join(name.lower().replace("-", " ").replace("_", " ").split())


def replica_intrinsics(hw: tuple[int, int]) -> np.ndarray:
    """K (3, 3) of Semantic-NeRF's Replica renders: 90° horizontal FoV, square pixels, centred."""
    h, w = hw
    f = w / 2.0  # w / (2 tan(45°))
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def read_class_table(path: Path) -> dict[int, str]:
    """Id -> name from ``info_semantic.json`` ({"classes": [{"id", "name"}]}), {"<id>": "<name>"} or an id/name TSV."""
    path = Path(path)
    text = read_file(path, f"class table missing; pass --classes with the scene's {CLASS_FILE}", text=True)
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
            if isinstance(data, dict) and isinstance(data.get("classes"), list):
                table = {int(c["id"]): str(c["name"]) for c in data["classes"]}
            else:
                table = {int(k): str(v) for k, v in data.items()}
        else:
            table = {int(r["id"]): str(r["name"]) for r in csv.DictReader(text.splitlines(), delimiter="\t")}
    except (ValueError, KeyError, TypeError, AttributeError) as e:
        raise ValueError(f"{path}: not a class table ({type(e).__name__}: {e}); expected Replica's "
                         f"{CLASS_FILE}, a JSON object {{id: name}} or a TSV with columns id and name") from None
    bad = [i for i in table if not 0 <= i < 65536]
    if bad:
        raise ValueError(f"{path}: class ids {bad} out of range 0..65535")
    return table


def find_class_table(src: Path) -> Path:
    """The default class table of a rendered sequence; error names the places and the fix."""
    candidates = [src / CLASS_FILE, src.resolve().parent / CLASS_FILE]
    for path in candidates:
        if path.is_file():
            return path
    raise FileNotFoundError(f"no class table for {src / 'semantic_class'} (looked for "
                            f"{', '.join(map(str, candidates))}); copy the scene's Replica/<scene>/habitat/"
                            f"{CLASS_FILE} there or pass --classes PATH (a JSON {{id: name}} or a TSV with columns id "
                            "and name also works)")


def class_lut(table: dict[int, str], space: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(lut (65536,) uint16 id -> label, known (65536,) bool, names mapped to ignore) for ``space``."""
    to_label = nyu40_to_label(space)
    nyu_ids = {normalise_name(n): i + 1 for i, n in enumerate(NYU40)}
    lut = np.full(65536, IGNORE_ID, dtype=np.uint16)
    known = np.zeros(65536, dtype=bool)
    known[0] = True  # 0 = void in the renders
    ignored: list[str] = []
    for class_id, name in table.items():
        norm = normalise_name(name)
        nyu_name = norm if norm in nyu_ids else REPLICA_TO_NYU40.get(norm)
        label = to_label.get(nyu_ids[normalise_name(nyu_name)]) if nyu_name is not None else None
        known[class_id] = True
        if label is None:
            ignored.append(name)
        else:
            lut[class_id] = label
    return lut, known, sorted(set(ignored))


def read_replica(src: Path, name: str, classes: Path | None = None, label_space: str = "scannet20",
                 size_hw: tuple[int, int] | None = None, frame_skip: int = 5, depth_scale: float = 1000.0) -> Scene:
    """Open a Semantic-NeRF Replica rendering as a canonical scene (views load lazily). Frames without a depth or
    semantic image or with a non-finite trajectory row go to ``meta.extra["dropped_frames"]``; every
    ``frame_skip``-th remaining one is kept. ``size_hw`` None keeps the rendered size (640 x 480)."""
    src = Path(src)
    for folder in ("rgb", "depth", "semantic_class"):
        if not (src / folder).is_dir():
            raise FileNotFoundError(f"{src / folder}: missing folder; is {src} a Semantic-NeRF Replica sequence?")
    if frame_skip < 1:
        raise ValueError(f"frame_skip must be >= 1, got {frame_skip}")
    traj_path = src / "traj_w_c.txt"
    try:
        traj = np.loadtxt(traj_path, dtype=np.float64, ndmin=2)
    except FileNotFoundError:
        raise FileNotFoundError(f"{traj_path}: missing; it ships with each rendered sequence") from None
    except ValueError:
        raise ValueError(f"{traj_path}: not a table of numbers") from None
    if traj.shape[1] != 16:
        raise ValueError(f"{traj_path}: each row must hold 16 numbers (a row-major 4x4), got {traj.shape[1]}")
    classes = Path(classes) if classes is not None else find_class_table(src)
    lut, known, ignored = class_lut(read_class_table(classes), label_space)

    rgbs = numbered_files(src / "rgb", r"rgb_(\d+)", (".png",))
    if not rgbs:
        raise FileNotFoundError(f"{src / 'rgb'}: no rgb_<i>.png frames")
    depths = numbered_files(src / "depth", r"depth_(\d+)", (".png",))
    sems = numbered_files(src / "semantic_class", r"semantic_class_(\d+)", (".png",))
    beyond = [frame for frame in rgbs if frame >= len(traj)]
    if beyond:
        raise ValueError(f"{traj_path}: {len(traj)} rows, but {rgbs[beyond[0]]} needs row {beyond[0]}; "
                         "use the trajectory rendered with these images")
    poses, ids, dropped = select_frames(
        src, rgbs, {"depth": depths, "semantic_class": sems}, lambda frame: traj[frame].reshape(4, 4),
        lambda frame: f"non-finite pose in row {frame} of traj_w_c.txt", frame_skip)

    def read_view(view_id: str) -> View:
        """Load, map and (optionally) resize one rendered frame."""
        frame = ids[view_id]
        rgb = read_rgb8(rgbs[frame])
        native_hw = rgb.shape[:2]
        hw = tuple(size_hw) if size_hw is not None else native_hw
        K_native = replica_intrinsics(native_hw)
        K = scale_intrinsics(K_native, native_hw, hw)
        depth, sem = read_depth_m(depths[frame], depth_scale), read_image(sems[frame])
        for path, image in ((depths[frame], depth), (sems[frame], sem)):
            if image.shape[:2] != native_hw:
                raise ValueError(f"{path}: size {image.shape[1]}x{image.shape[0]} differs from "
                                 f"{rgbs[frame].name} ({native_hw[1]}x{native_hw[0]})")
        if sem.ndim != 2 or sem.dtype not in (np.uint8, np.uint16):
            raise ValueError(f"{sems[frame]}: class ids must be a single-channel 8/16-bit PNG")
        unknown = np.unique(sem[~known[sem]])
        if unknown.size:
            raise ValueError(f"{sems[frame]}: class ids {unknown.tolist()} are not listed in {classes}; "
                             "is that the class table of this scene?")
        return View(view_id=view_id, rgb=resize_rgb(rgb, hw), depth=resample_nearest(depth, K_native, K, hw, 0.0),
                    label=lut[resample_nearest(sem, K_native, K, hw, 0)], K=K, c2w=poses[frame])

    meta = SceneMeta(name=name, label_space=label_space, class_names=class_names(label_space), view_ids=list(ids),
                     splits={}, extra={"source_format": "replica", "source": str(src), "class_table": str(classes),
                                       "ignored_classes": ignored, "frame_skip": frame_skip, "dropped_frames": dropped})
    return Scene(meta=meta, read_view=read_view)
