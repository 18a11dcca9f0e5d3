"""Test helper: pack a ScanNet export (``write_scannet_export``'s layout) into a raw scan, ``<scan>.sens`` in
ScanNet's documented binary layout plus ``<scan>_2d-label-filt.zip``, and make the export hold exactly the
same content (JPEG colour bytes, float32 poses and intrinsics), so both readers can be compared.
"""

from __future__ import annotations

import struct
import zipfile
import zlib
from pathlib import Path

import cv2
import numpy as np

COLOR_JPEG, DEPTH_ZLIB = 2, 1


def _float32_text(m: np.ndarray) -> str:
    return "\n".join(" ".join(f"{float(x):.9g}" for x in row) for row in m.astype(np.float32)) + "\n"


def pack_sens(export: Path, scan_dir: Path, scan: str, invalid_pose_frames: tuple[int, ...] = (),
              unlabelled_frames: tuple[int, ...] = ()) -> Path:
    """Write ``scan_dir/<scan>.sens`` and ``scan_dir/<scan>_2d-label-filt.zip`` from ``export`` and rewrite the
    export to the same content. Frames listed in ``invalid_pose_frames`` get -inf poses (in both); frames in
    ``unlabelled_frames`` lose their label image (in both)."""
    frames = sorted(int(p.stem) for p in (export / "color").glob("*.png"))
    K_color = np.loadtxt(export / "intrinsic" / "intrinsic_color.txt")
    K_depth = np.loadtxt(export / "intrinsic" / "intrinsic_depth.txt")
    for name, K in (("intrinsic_color.txt", K_color), ("intrinsic_depth.txt", K_depth)):
        (export / "intrinsic" / name).write_text(_float32_text(K))
    first = cv2.imread(str(export / "color" / f"{frames[0]}.png"))
    depth0 = cv2.imread(str(export / "depth" / f"{frames[0]}.png"), cv2.IMREAD_UNCHANGED)
    scan_dir.mkdir(parents=True, exist_ok=True)
    name = b"StructureSensor"
    body = [struct.pack("<IQ", 4, len(name)), name]
    for m in (K_color, np.eye(4), K_depth, np.eye(4)):
        body.append(np.asarray(m, "<f4").tobytes())
    body.append(struct.pack("<iiIIIIfQ", COLOR_JPEG, DEPTH_ZLIB, first.shape[1], first.shape[0], depth0.shape[1],
                            depth0.shape[0], 1000.0, len(frames)))
    with zipfile.ZipFile(scan_dir / f"{scan}_2d-label-filt.zip", "w") as z:
        for i in frames:
            bgr = cv2.imread(str(export / "color" / f"{i}.png"))
            jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()
            (export / "color" / f"{i}.png").unlink()
            (export / "color" / f"{i}.jpg").write_bytes(jpeg)
            depth = cv2.imread(str(export / "depth" / f"{i}.png"), cv2.IMREAD_UNCHANGED)
            c2w = np.loadtxt(export / "pose" / f"{i}.txt")
            if i in invalid_pose_frames:
                c2w[:] = -np.inf
            (export / "pose" / f"{i}.txt").write_text(_float32_text(c2w))
            label_png = export / "label-filt" / f"{i}.png"
            if i in unlabelled_frames:
                label_png.unlink()
            else:
                z.write(label_png, f"label-filt/{i}.png")
            packed = zlib.compress(depth.astype("<u2").tobytes())
            body.append(np.asarray(c2w, "<f4").tobytes())
            body.append(struct.pack("<QQQQ", 1000 * i, 1000 * i + 1, len(jpeg), len(packed)))
            body += [jpeg, packed]
    path = scan_dir / f"{scan}.sens"
    path.write_bytes(b"".join(body))
    return path
