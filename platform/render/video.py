"""A fly-through as a VP8 WebM, an MPEG-4 part 2 MP4 and a GIF preview (docs/render.md), written into the staging
folder ``.<stem>.tmp<pid>`` and renamed into place by :meth:`VideoSet.finish`, so none is ever left half-written."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

GIF_WIDTH = 480  # widest GIF preview in pixels (larger frames are scaled down)
GIF_FRAMES = 60  # most frames in a GIF preview (longer videos keep every k-th frame)
CODECS = {"webm": "VP80", "mp4": "mp4v"}  # video file suffix -> OpenCV fourcc


class VideoSet:
    """The WebM, MP4 and GIF of one fly-through (module doc); a context manager that cleans up on error."""

    def __init__(self, out_dir: Path, stem: str, fps: float, size_hw: tuple[int, int], n_frames: int) -> None:
        """Open the writers for ``n_frames`` frames of ``size_hw`` = (H, W) at ``fps`` under ``out_dir/<stem>.*``."""
        self.out_dir, self.stem, self.fps, self.size_hw = Path(out_dir), stem, float(fps), size_hw
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.staging = self.out_dir / f".{stem}.tmp{os.getpid()}"
        shutil.rmtree(self.staging, ignore_errors=True)
        self.staging.mkdir()
        self.gif_every = max(1, -(-n_frames // GIF_FRAMES))
        self._gif: list[Image.Image] = []
        self._count = 0
        self._writers: dict[str, cv2.VideoWriter] = {}
        h, w = size_hw
        for suffix, fourcc in CODECS.items():
            path = self.staging / f"{stem}.{suffix}"
            writer = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*fourcc), self.fps, (w, h))
            if not writer.isOpened():
                self.abort()
                raise OSError(f"{self.out_dir / path.name}: OpenCV could not open a {fourcc} video writer; this "
                              "OpenCV build lacks FFmpeg (install opencv-contrib-python-headless as pinned)")
            self._writers[suffix] = writer

    def write(self, frame: np.ndarray) -> None:
        """Append a uint8 (H, W, 3) RGB frame of the size given at opening."""
        if frame.shape != (*self.size_hw, 3) or frame.dtype != np.uint8:
            raise ValueError(f"frame {self._count}: {frame.dtype} {frame.shape}, expected uint8 {(*self.size_hw, 3)}")
        bgr = np.ascontiguousarray(frame[..., ::-1])
        for writer in self._writers.values():
            writer.write(bgr)
        if self._count % self.gif_every == 0:
            image = Image.fromarray(frame)
            if image.width > GIF_WIDTH:
                size = (GIF_WIDTH, round(image.height * GIF_WIDTH / image.width))
                image = image.resize(size, Image.Resampling.LANCZOS)
            self._gif.append(image.quantize(colors=256, method=Image.Quantize.MEDIANCUT))
        self._count += 1

    def finish(self, extra: dict[str, bytes]) -> dict[str, Path]:
        """Close the videos, write the GIF and ``extra`` (name -> bytes), rename all into place; {name: final path}."""
        self._release()
        if not self._gif:
            self.abort()
            raise ValueError(f"{self.out_dir}: no frame was written; a video needs at least one")
        duration_ms = max(20, int(round(1000.0 * self.gif_every / self.fps)))
        self._gif[0].save(self.staging / f"{self.stem}.gif", format="GIF", save_all=True, append_images=self._gif[1:],
                          duration=duration_ms, loop=0)
        for name, data in extra.items():
            (self.staging / name).write_bytes(data)
        names = {**{s: f"{self.stem}.{s}" for s in (*CODECS, "gif")}, **{name: name for name in extra}}
        for name in names.values():
            os.replace(self.staging / name, self.out_dir / name)
        shutil.rmtree(self.staging, ignore_errors=True)
        return {key: self.out_dir / name for key, name in names.items()}

    def _release(self) -> None:
        for writer in self._writers.values():
            writer.release()
        self._writers = {}

    def abort(self) -> None:
        """Release the writers and remove the staging folder (nothing reaches the output folder)."""
        self._release()
        shutil.rmtree(self.staging, ignore_errors=True)

    def __enter__(self) -> VideoSet:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *_: object) -> None:
        if exc_type is not None:
            self.abort()
