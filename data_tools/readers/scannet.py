"""Reader: one ScanNet scan exported by ScanNet's SensReader with its ``label-filt/`` unzipped (``color/``,
``depth/``, ``pose/``, ``intrinsic/``); raw label ids -> NYU40 -> label space through
``scannetv2-labels.combined.tsv``, depth and labels resampled into the target colour camera.
Layout and rules: docs/data.md, "ScanNet exported frames"."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sray.data_tools.label_spaces import class_names
from sray.data_tools.readers.common import (check_principal_point, numbered_files, nyu40_to_label, read_depth_m,
                                            read_file, read_image, read_rgb8, resample_nearest, resize_rgb,
                                            scale_intrinsics, select_frames)
from sray.data_tools.scene import IGNORE_ID, Scene, SceneMeta, View

TSV_NAME = "scannetv2-labels.combined.tsv"
_FOLDER_FIX = {folder: f"export the .sens file with ScanNet's SensReader (--export_{flag})" for folder, flag in
               (("color", "color_images"), ("depth", "depth_images"), ("pose", "poses"), ("intrinsic", "intrinsics"))}
_FOLDER_FIX["label-filt"] = "unzip <scan>_2d-label-filt.zip into SRC (it holds label-filt/<i>.png)"


def read_label_tsv(tsv: Path) -> dict[int, int]:
    """Raw ScanNet label id -> NYU40 id (0 = none) from ``scannetv2-labels.combined.tsv``."""
    tsv = Path(tsv)
    text = read_file(tsv, f"missing; pass --tsv with the path of ScanNet's {TSV_NAME}", text=True)
    rows = list(csv.reader(text.splitlines(), delimiter="\t"))
    if not rows:
        raise ValueError(f"{tsv}: empty; expected ScanNet's {TSV_NAME}")
    header = [h.strip() for h in rows[0]]
    for column in ("id", "nyu40id"):
        if column not in header:
            raise ValueError(f"{tsv}: column {column!r} is missing (header has {header}); "
                             f"use ScanNet's {TSV_NAME}, whose header names both 'id' and 'nyu40id'")
    id_col, nyu_col = header.index("id"), header.index("nyu40id")
    mapping: dict[int, int] = {}
    for line_no, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue
        try:
            raw = int(row[id_col])
            cell = row[nyu_col].strip() if nyu_col < len(row) else ""
            nyu = int(cell) if cell else 0
        except (ValueError, IndexError):
            raise ValueError(f"{tsv}, line {line_no}: 'id' and 'nyu40id' must be integers, got {row}") from None
        if not (0 <= raw < 65536 and 0 <= nyu <= 40):
            raise ValueError(f"{tsv}, line {line_no}: id {raw} or nyu40id {nyu} out of range (0..65535, 0..40)")
        if mapping.get(raw, nyu) != nyu:
            raise ValueError(f"{tsv}, line {line_no}: raw id {raw} listed twice with different nyu40ids")
        mapping[raw] = nyu
    return mapping


def raw_label_lut(raw_to_nyu40: dict[int, int], space: str) -> np.ndarray:
    """Lookup table (65536,) uint16: raw ScanNet id -> label id in ``space`` (IGNORE_ID if none, and for 0)."""
    to_label = nyu40_to_label(space)
    lut = np.full(65536, IGNORE_ID, dtype=np.uint16)
    for raw, nyu in raw_to_nyu40.items():
        if nyu in to_label:
            lut[raw] = to_label[nyu]
    lut[0] = IGNORE_ID  # raw id 0 marks unannotated pixels in ScanNet
    return lut


def find_tsv(src: Path) -> Path:
    """The label tsv next to the scan or up to three folders above it; error lists where it looked."""
    candidates = [folder / TSV_NAME for folder in [src, *list(src.resolve().parents)[:3]]]
    for path in candidates:
        if path.is_file():
            return path
    raise FileNotFoundError(f"{TSV_NAME} not found (looked in {', '.join(str(p.parent) for p in candidates)}); "
                            "pass --tsv with its path (it ships with the ScanNet download)")


def read_matrix4(path: Path) -> np.ndarray:
    """A 4 x 4 matrix of numbers from a whitespace-separated text file, float64."""
    try:
        m = np.loadtxt(path, dtype=np.float64)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing") from None
    except ValueError:
        raise ValueError(f"{path}: not a 4x4 matrix of numbers") from None
    if m.shape != (4, 4):
        raise ValueError(f"{path}: expected a 4x4 matrix, got shape {m.shape}")
    return m


@dataclass(frozen=True)
class FrameCameras:
    """The colour and depth intrinsics (3, 3) of a scan at their images' resolutions, with where they were read."""

    K_color: np.ndarray
    K_depth: np.ndarray
    color_where: str
    depth_where: str


def frame_view(view_id: str, rgb: np.ndarray, depth_m: np.ndarray, raw_label: np.ndarray, c2w: np.ndarray,
               cameras: FrameCameras, size_hw: tuple[int, int] | None, lut: np.ndarray, label_where: str) -> View:
    """One ScanNet frame (colour uint8 (Hc, Wc, 3), depth float32 metres (Hd, Wd), raw label ids (Hl, Wl)) in
    the target colour camera of size ``size_hw`` (None: the colour size); labels mapped through ``lut``."""
    color_hw = rgb.shape[:2]
    check_principal_point(cameras.K_color, color_hw, cameras.color_where)
    hw = tuple(size_hw) if size_hw is not None else color_hw
    K = scale_intrinsics(cameras.K_color, color_hw, hw)
    check_principal_point(cameras.K_depth, depth_m.shape, cameras.depth_where)
    if raw_label.ndim != 2 or raw_label.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{label_where}: labels must be a single-channel 8/16-bit PNG")
    K_label = scale_intrinsics(cameras.K_color, color_hw, raw_label.shape)
    return View(view_id=view_id, rgb=resize_rgb(rgb, hw), depth=resample_nearest(depth_m, cameras.K_depth, K, hw, 0.0),
                label=lut[resample_nearest(raw_label, K_label, K, hw, 0)], K=K, c2w=c2w)


def read_scannet(src: Path, name: str, tsv: Path | None = None, label_space: str = "scannet20",
                 size_hw: tuple[int, int] | None = (240, 320), frame_skip: int = 10,
                 depth_scale: float = 1000.0) -> Scene:
    """Open a ScanNet export as a scene (views load lazily, ids zero-padded frame numbers); frames without depth, pose
    or label or with a -inf/NaN pose go to ``meta.extra["dropped_frames"]``, every ``frame_skip``-th other is kept."""
    src = Path(src)
    for folder, fix in _FOLDER_FIX.items():
        if not (src / folder).is_dir():
            raise FileNotFoundError(f"{src / folder}: missing folder; {fix}")
    if frame_skip < 1:
        raise ValueError(f"frame_skip must be >= 1, got {frame_skip}")
    tsv = Path(tsv) if tsv is not None else find_tsv(src)
    lut = raw_label_lut(read_label_tsv(tsv), label_space)
    k_color_path, k_depth_path = src / "intrinsic" / "intrinsic_color.txt", src / "intrinsic" / "intrinsic_depth.txt"
    K_color, K_depth = read_matrix4(k_color_path)[:3, :3], read_matrix4(k_depth_path)[:3, :3]

    colors = numbered_files(src / "color", r"(\d+)", (".jpg", ".jpeg", ".png"))
    if not colors:
        raise FileNotFoundError(f"{src / 'color'}: no <i>.jpg or <i>.png frames; {_FOLDER_FIX['color']}")
    others = {kind: numbered_files(src / folder, r"(\d+)", (suffix,)) for kind, folder, suffix in
              (("depth", "depth", ".png"), ("pose", "pose", ".txt"), ("label", "label-filt", ".png"))}
    poses, ids, dropped = select_frames(
        src, colors, others, lambda frame: read_matrix4(others["pose"][frame]),
        lambda frame: f"invalid pose in {others['pose'][frame].name} (-inf or NaN entries)", frame_skip)

    def read_view(view_id: str) -> View:
        """Load one exported frame and bring it into the target colour camera."""
        frame = ids[view_id]
        raw = read_image(others["label"][frame])
        return frame_view(view_id, read_rgb8(colors[frame]), read_depth_m(others["depth"][frame], depth_scale), raw,
                          poses[frame], FrameCameras(K_color, K_depth, str(k_color_path), str(k_depth_path)),
                          size_hw, lut, str(others["label"][frame]))

    meta = SceneMeta(name=name, label_space=label_space, class_names=class_names(label_space), view_ids=list(ids),
                     splits={}, extra={"source_format": "scannet", "source": str(src), "label_tsv": str(tsv),
                                       "frame_skip": frame_skip, "dropped_frames": dropped})
    return Scene(meta=meta, read_view=read_view)
