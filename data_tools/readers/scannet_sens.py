"""Reader: a raw ScanNet scan, ``SRC/<scan>.sens`` and ``SRC/<scan>_2d-label-filt.zip`` (label-filt/<frame>.png, 16-bit
raw label ids) read directly, without SensReader export or unzipping. The ``.sens`` layout (ScanNet's SensReader,
little-endian): header ``uint32`` version (4); ``uint64`` n + n bytes sensor name; four ``float32`` 4 x 4 matrices
(colour intrinsics, colour extrinsics, depth intrinsics, depth extrinsics); ``int32`` colour compression (0 raw, 1 PNG,
2 JPEG) and depth compression (0 raw uint16, 1 zlib uint16); ``uint32`` colour width, height, depth width, height;
``float32`` depth shift (units per metre); ``uint64`` frame count. Each frame: ``float32`` 4 x 4 camera-to-world;
``uint64`` colour and depth timestamps and byte counts; the colour bytes; the depth bytes. Streamed once to index the
frames, then read by seeking; everything after decoding is ``readers.scannet``'s (docs/data.md, "A raw ScanNet scan in
one step")."""

from __future__ import annotations

import struct
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import cv2
import numpy as np
from tqdm import tqdm

from sray.data_tools.label_spaces import class_names
from sray.data_tools.readers.common import kept_view_ids
from sray.data_tools.readers.scannet import FrameCameras, find_tsv, frame_view, raw_label_lut, read_label_tsv
from sray.data_tools.scene import Scene, SceneMeta, View

COLOR_CODECS = {0: "raw", 1: "png", 2: "jpeg"}
"""Colour compression ids of the .sens header that this reader decodes."""
DEPTH_CODECS = {0: "raw_ushort", 1: "zlib_ushort"}
"""Depth compression ids of the .sens header that this reader decodes."""
_FRAME_HEAD = struct.Struct("<16f4Q")
"""camera-to-world, colour and depth timestamps, colour and depth byte counts."""


@dataclass(frozen=True)
class SensHeader:
    """What the .sens header says about the whole scan (intrinsics (3, 3) float64)."""

    sensor: str
    K_color: np.ndarray
    K_depth: np.ndarray
    color_codec: int
    depth_codec: int
    color_hw: tuple[int, int]
    depth_hw: tuple[int, int]
    depth_shift: float
    """Depth units per metre (ScanNet: 1000)."""
    n_frames: int


@dataclass(frozen=True)
class SensFrame:
    """Where one frame's colour bytes (then its depth bytes) lie in the file; its float64 (4, 4) c2w (-inf: invalid)."""

    c2w: np.ndarray
    color_at: int
    color_bytes: int
    depth_bytes: int


def _read(f: BinaryIO, n: int, path: Path, what: str) -> bytes:
    """The next ``n`` bytes of ``f``; ValueError naming ``what`` when the file ends first."""
    data = f.read(n)
    if len(data) != n:
        raise ValueError(f"{path}: file ends inside the {what} ({len(data)} of {n} bytes); the .sens file is "
                         "truncated, download it again")
    return data


def read_sens_header(f: BinaryIO, path: Path) -> SensHeader:
    """Parse the header at the start of ``f``; ValueError names the file, the field and the fix."""
    (version,) = struct.unpack("<I", _read(f, 4, path, "header version"))
    if version != 4:
        raise ValueError(f"{path}: .sens version {version}; this reader reads version 4 (ScanNet v2's files)")
    (n_name,) = struct.unpack("<Q", _read(f, 8, path, "sensor name length"))
    if n_name > 4096:
        raise ValueError(f"{path}: sensor name length {n_name} is not plausible; is this a ScanNet .sens file?")
    sensor = _read(f, n_name, path, "sensor name").decode("utf-8", "replace")
    mats = np.frombuffer(_read(f, 4 * 16 * 4, path, "calibration matrices"), "<f4").reshape(4, 4, 4)
    color_codec, depth_codec, cw, ch, dw, dh, shift, n_frames = struct.unpack(
        "<iiIIIIfQ", _read(f, 4 * 7 + 8, path, "image sizes and codecs"))
    for what, codec, readable in (("colour", color_codec, COLOR_CODECS), ("depth", depth_codec, DEPTH_CODECS)):
        if codec not in readable:
            raise ValueError(f"{path}: {what} compression {codec} is not read here (readable: {readable}); export the "
                             "scan with ScanNet's SensReader and use --format scannet")
    if shift <= 0:
        raise ValueError(f"{path}: header depth shift is {shift}; it must be > 0 (ScanNet: 1000 units per metre)")
    return SensHeader(sensor, mats[0, :3, :3].astype(np.float64), mats[2, :3, :3].astype(np.float64),
                      color_codec, depth_codec, (ch, cw), (dh, dw), float(shift), n_frames)


def index_frames(f: BinaryIO, header: SensHeader, path: Path, progress: bool) -> list[SensFrame]:
    """Stream over every frame once: its pose and the offsets of its bytes (the bytes are skipped)."""
    frames = []
    for _ in tqdm(range(header.n_frames), desc=f"{path.name}: index", unit="frame", disable=not progress):
        values = _FRAME_HEAD.unpack(_read(f, _FRAME_HEAD.size, path, f"head of frame {len(frames)}"))
        color_bytes, depth_bytes = values[18], values[19]
        color_at = f.tell()
        frames.append(SensFrame(np.array(values[:16], np.float64).reshape(4, 4), color_at, color_bytes, depth_bytes))
        f.seek(color_bytes + depth_bytes, 1)
    end = f.tell()
    f.seek(0, 2)
    if f.tell() < end:
        raise ValueError(f"{path}: file ends inside frame {len(frames) - 1}'s images; the .sens file is truncated, "
                         "download it again")
    return frames


def decode_color(data: bytes, header: SensHeader, where: str) -> np.ndarray:
    """One frame's colour as uint8 (H, W, 3) RGB."""
    if header.color_codec == 0:
        h, w = header.color_hw
        if len(data) != h * w * 3:
            raise ValueError(f"{where}: raw colour has {len(data)} bytes, {h}x{w}x3 expected")
        return np.frombuffer(data, np.uint8).reshape(h, w, 3).copy()
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError(f"{where}: colour bytes are not a readable {COLOR_CODECS[header.color_codec]} image")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def decode_depth(data: bytes, header: SensHeader, where: str) -> np.ndarray:
    """One frame's depth as float32 (H, W) metres (0 = unknown)."""
    try:
        raw = zlib.decompress(data) if header.depth_codec == 1 else data
    except zlib.error as e:
        raise ValueError(f"{where}: depth bytes are not zlib data ({e})") from None
    h, w = header.depth_hw
    if len(raw) != h * w * 2:
        raise ValueError(f"{where}: depth has {len(raw)} bytes, {h}x{w} uint16 expected")
    return np.frombuffer(raw, "<u2").reshape(h, w).astype(np.float32) / np.float32(header.depth_shift)


def find_label_zip(src: Path) -> Path:
    """``SRC/<scan>_2d-label-filt.zip`` (or the one such zip in SRC); FileNotFoundError says how to get it."""
    candidates = sorted(src.glob("*_2d-label-filt.zip"))
    if len(candidates) == 1:
        return candidates[0]
    raise FileNotFoundError(f"{src}: {len(candidates)} files named <scan>_2d-label-filt.zip (one expected); "
                            "download it with the scan (ScanNet's --type _2d-label-filt.zip) or pass --labels")


def read_scannet_sens(src: Path, name: str, tsv: Path | None = None, labels: Path | None = None,
                      label_space: str = "scannet20", size_hw: tuple[int, int] | None = (240, 320),
                      frame_skip: int = 10, depth_scale: float = 1000.0, progress: bool = True) -> Scene:
    """Open a raw ScanNet scan folder as a canonical scene (views load lazily). ``depth_scale`` is ignored (the
    header has the depth shift); frames without a label image or valid pose go to ``extra["dropped_frames"]``."""
    src = Path(src)
    sens_files = sorted(src.glob("*.sens"))
    if len(sens_files) != 1:
        raise FileNotFoundError(f"{src}: {len(sens_files)} .sens files (one expected: <scan>.sens); pass the folder "
                                "of one ScanNet scan")
    sens = sens_files[0]
    label_zip = Path(labels) if labels is not None else find_label_zip(src)
    tsv = Path(tsv) if tsv is not None else find_tsv(src)
    lut = raw_label_lut(read_label_tsv(tsv), label_space)
    with open(sens, "rb") as f:
        header = read_sens_header(f, sens)
        frames = index_frames(f, header, sens, progress)
    try:
        members = {Path(n).stem: n for n in zipfile.ZipFile(label_zip).namelist() if n.endswith(".png")}
    except (zipfile.BadZipFile, FileNotFoundError) as e:
        raise ValueError(f"{label_zip}: not a readable zip ({e}); download <scan>_2d-label-filt.zip again") from None
    dropped: dict[str, str] = {}
    poses: dict[int, np.ndarray] = {}
    for i, frame in enumerate(frames):
        if str(i) not in members:
            dropped[str(i)] = f"no label-filt/{i}.png in {label_zip.name}"
        elif not np.isfinite(frame.c2w).all():
            dropped[str(i)] = "invalid pose in the .sens stream (-inf or NaN entries)"
        else:
            poses[i] = frame.c2w
    ids = kept_view_ids(poses, frame_skip, src, dropped)
    cameras = FrameCameras(header.K_color, header.K_depth, f"{sens} (colour intrinsics)", f"{sens} (depth intrinsics)")

    def read_view(view_id: str) -> View:
        """Seek to one frame's bytes, decode them and bring them into the target colour camera."""
        i = ids[view_id]
        frame, where = frames[i], f"{sens}, frame {i}"
        with open(sens, "rb") as f:
            f.seek(frame.color_at)
            rgb = decode_color(_read(f, frame.color_bytes, sens, f"colour of frame {i}"), header, where)
            depth = decode_depth(_read(f, frame.depth_bytes, sens, f"depth of frame {i}"), header, where)
        with zipfile.ZipFile(label_zip) as z:
            raw = cv2.imdecode(np.frombuffer(z.read(members[str(i)]), np.uint8), cv2.IMREAD_UNCHANGED)
        if raw is None:
            raise ValueError(f"{label_zip}:{members[str(i)]}: not a readable PNG")
        return frame_view(view_id, rgb, depth, raw, poses[i], cameras, size_hw, lut, f"{label_zip}:{members[str(i)]}")

    meta = SceneMeta(name=name, label_space=label_space, class_names=class_names(label_space), view_ids=list(ids),
                     splits={}, extra={"source_format": "scannet-sens", "source": str(sens), "labels": str(label_zip),
                            "label_tsv": str(tsv), "frame_skip": frame_skip, "dropped_frames": dropped,
                            "sensor": header.sensor, "depth_shift": header.depth_shift})
    return Scene(meta=meta, read_view=read_view)
