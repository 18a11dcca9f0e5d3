"""Test helpers: write a canonical scene as a reader's source (a ScanNet export, a Replica sequence).

For the readers' round-trip tests and fixtures (``from source_writers import ...``; tests/conftest.py
puts tests/ on sys.path). They write at the scene's own resolution and store colour losslessly
(``color/<i>.png``, which the ScanNet reader accepts beside ``<i>.jpg``), so reading the result back
reproduces the scene: labels exactly, cameras to float precision, depth to the 1 mm of the 16-bit
PNGs. Frames are numbered 0..n-1 in view order. Every file is written atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sray.data_tools.atomic import atomic_write_bytes, atomic_write_json
from sray.data_tools.png import depth_to_png16, encode_png
from sray.data_tools.readers.common import nyu40_to_label
from sray.data_tools.readers.replica import CLASS_FILE, replica_intrinsics
from sray.data_tools.readers.scannet import read_label_tsv
from sray.data_tools.scene import Scene


def _matrix_text(m: np.ndarray) -> bytes:
    """Rows of a matrix as whitespace-separated text with round-trip precision."""
    return ("\n".join(" ".join(f"{x:.17g}" for x in row) for row in np.atleast_2d(m)) + "\n").encode()


def label_to_raw_lut(tsv_path: Path, space: str, ignore_id: int) -> np.ndarray:
    """(65536,) int64: label id of ``space`` -> the smallest raw ScanNet id the tsv maps to it.

    ``ignore_id`` -> raw 0 (unannotated); label ids no raw id maps to hold -1.
    """
    to_label = nyu40_to_label(space)
    lut = np.full(65536, -1, dtype=np.int64)
    for raw, nyu in sorted(read_label_tsv(tsv_path).items(), reverse=True):
        if raw > 0 and nyu in to_label:
            lut[to_label[nyu]] = raw
    lut[ignore_id] = 0
    return lut


def write_scannet_export(scene: Scene, dst: Path, tsv_path: Path) -> Path:
    """Write ``scene`` as a ScanNet export under ``dst``; labels become raw ids via ``tsv_path``.

    All views must share one K (ScanNet stores one colour and one depth intrinsic per scan); both
    intrinsic files get it, since depth is written in the colour camera. Raises ValueError naming
    the view when K differs or a label id has no raw id in the tsv.
    """
    dst = Path(dst)
    to_raw = label_to_raw_lut(tsv_path, scene.meta.label_space, scene.meta.ignore_id)
    K0 = None
    for frame, view in enumerate(scene.views()):
        if K0 is None:
            K0 = np.asarray(view.K, np.float64)
        elif not np.allclose(view.K, K0, rtol=0, atol=1e-9):
            raise ValueError(f"view {view.view_id!r}: K differs from the first view's; a ScanNet export "
                             "holds one intrinsic matrix per scan")
        raw = to_raw[view.label.astype(np.int64)]
        if (raw < 0).any():
            missing = np.unique(view.label[raw < 0]).tolist()
            raise ValueError(f"view {view.view_id!r}: label ids {missing} have no raw id in {tsv_path}")
        atomic_write_bytes(dst / "color" / f"{frame}.png", encode_png(view.rgb))
        atomic_write_bytes(dst / "depth" / f"{frame}.png", encode_png(depth_to_png16(view.depth)))
        atomic_write_bytes(dst / "label-filt" / f"{frame}.png", encode_png(raw.astype(np.uint16)))
        atomic_write_bytes(dst / "pose" / f"{frame}.txt", _matrix_text(view.c2w))
    if K0 is None:
        raise ValueError(f"scene {scene.meta.name!r} has no views to write")
    K4 = np.eye(4)
    K4[:3, :3] = K0
    for name in ("intrinsic_color.txt", "intrinsic_depth.txt"):
        atomic_write_bytes(dst / "intrinsic" / name, _matrix_text(K4))
    return dst


def write_replica(scene: Scene, dst: Path) -> Path:
    """Write ``scene`` in Semantic-NeRF's Replica layout under ``dst``, plus ``info_semantic.json``.

    Class ids are label id + 1 (0 = void = IGNORE_ID) and the class table names them with the scene's
    class names. The layout implies a 90° horizontal FoV, so every view's K must equal
    :func:`replica_intrinsics` for its size; ValueError names the view otherwise.
    """
    dst = Path(dst)
    meta = scene.meta
    sem_dtype = np.uint8 if len(meta.class_names) < 255 else np.uint16
    rows = []
    for frame, view in enumerate(scene.views()):
        if not np.allclose(view.K, replica_intrinsics(view.hw), rtol=0, atol=1e-9):
            raise ValueError(f"view {view.view_id!r}: K is not the 90° FoV camera of the Replica layout "
                             f"(fx = fy = W/2, centred); got {np.asarray(view.K).tolist()}")
        sem = np.where(view.label == meta.ignore_id, 0, view.label.astype(np.int64) + 1).astype(sem_dtype)
        atomic_write_bytes(dst / "rgb" / f"rgb_{frame}.png", encode_png(view.rgb))
        atomic_write_bytes(dst / "depth" / f"depth_{frame}.png", encode_png(depth_to_png16(view.depth)))
        atomic_write_bytes(dst / "semantic_class" / f"semantic_class_{frame}.png", encode_png(sem))
        rows.append(np.asarray(view.c2w, np.float64).reshape(16))
    if not rows:
        raise ValueError(f"scene {meta.name!r} has no views to write")
    atomic_write_bytes(dst / "traj_w_c.txt", _matrix_text(np.stack(rows)))
    table = {"classes": [{"id": i + 1, "name": name} for i, name in enumerate(meta.class_names)]}
    atomic_write_json(dst / CLASS_FILE, table)
    return dst
