"""The reader registry: every source format ``sray data convert`` reads, with its defaults and options; the CLI builds
its parser from it, so it imports neither numpy nor OpenCV (a reader's module is imported when used). A new format:
a module here whose ``read_<module>(src, name=..., label_space=..., size_hw=..., frame_skip=..., depth_scale=...,
**options)`` returns a canonical ``Scene``, plus a :class:`Reader` entry (docs/data.md, "Readers and validation")."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sray.data_tools.scene import Scene

ReadFunction = Callable[..., "Scene"]
"""``read(src, *, name, label_space, size_hw, frame_skip, depth_scale, **options) -> Scene``."""


@dataclass(frozen=True)
class ReaderOption:
    """A side input only one reader takes (a file path), offered as ``--<name>`` by ``sray data convert``."""

    name: str
    """Keyword of the read function and key of ``ConvertConfig.options``; a flag of the one ``sray data convert``
    command, so readers share a name only for the same file (both ScanNet readers' ``tsv``)."""
    help: str
    """What the file is and where the reader looks when it is not given (CLI help)."""
    type: Callable[[str], object] = Path
    """Parses the flag's text: a path, or ``float`` for a number (``--scale``)."""


@dataclass(frozen=True)
class Reader:
    """One source format: its name, what it reads, how to load it and its defaults."""

    name: str
    """Format name (``--format``)."""
    summary: str
    """The source, in a few words (CLI help and error messages)."""
    load: Callable[[], ReadFunction]
    """Returns the read function (importing the reader module on first use)."""
    size_hw: tuple[int, int] | None
    """Default output (H, W); None = the source's own image size."""
    frame_skip: int
    """Default: keep every n-th usable frame."""
    options: tuple[ReaderOption, ...] = ()
    """Reader-specific side inputs."""


def _lazy(module: str) -> Callable[[], ReadFunction]:
    """A ``Reader.load`` importing ``readers.<module>`` on first use and returning its ``read_<module>``."""
    return lambda: getattr(importlib.import_module(f"sray.data_tools.readers.{module}"), f"read_{module}")


SCALE_OPTION = ReaderOption("scale", "metres per capture unit (default: measured from metric depth maps against the "
                                     "capture's 3D points; without both, conversion stops and asks for it)", float)
"""Shared by the capture readers, whose units are arbitrary."""

READERS: dict[str, Reader] = {r.name: r for r in (
    # 320x240 is the paper's size; every 10th frame of the 30 fps scan.
    Reader(name="scannet", summary="ScanNet SensReader export + label-filt", load=_lazy("scannet"),
           size_hw=(240, 320), frame_skip=10,
           options=(ReaderOption("tsv", "scannetv2-labels.combined.tsv (default: searched next to and above SRC)"),)),
    # The same scan read raw: <scan>.sens and <scan>_2d-label-filt.zip, no export or unzip step.
    Reader(name="scannet-sens", summary="raw ScanNet scan: <scan>.sens + <scan>_2d-label-filt.zip",
           load=_lazy("scannet_sens"), size_hw=(240, 320), frame_skip=10,
           options=(ReaderOption("tsv", "scannetv2-labels.combined.tsv (default: searched next to and above SRC)"),
                    ReaderOption("labels", "<scan>_2d-label-filt.zip (default: the one such zip in SRC)"))),
    # The rendered size (640x480 in Semantic-NeRF's release, the paper's size); every 5th frame.
    Reader(name="replica", summary="Replica as rendered for Semantic-NeRF", load=_lazy("replica"),
           size_hw=None, frame_skip=5,
           options=(ReaderOption("classes", "class table, e.g. Replica/<scene>/habitat/info_semantic.json "
                                            "(default: SRC/info_semantic.json or SRC/../info_semantic.json)"),)),
    # Captures without labels (inference only): 320x240 like the paper's scans; every frame (already sparse).
    Reader(name="nerfstudio", summary="nerfstudio capture: transforms.json + images (+ depth), no labels",
           load=_lazy("nerfstudio"), size_hw=(240, 320), frame_skip=1, options=(SCALE_OPTION,)),
    Reader(name="colmap", summary="COLMAP capture: sparse/0/{cameras,images,points3D}.{bin,txt} + images/, no labels",
           load=_lazy("colmap"), size_hw=(240, 320), frame_skip=1,
           options=(SCALE_OPTION, ReaderOption("images", "image folder (default: SRC/images)"),
                    ReaderOption("sparse", "model folder (default: SRC, SRC/sparse/0, SRC/sparse or "
                                           "SRC/colmap/sparse/0, the first holding cameras.bin/.txt)"))),
)}
"""Every known source format by name."""


def get_reader(name: str) -> Reader:
    """The registered reader of format ``name``; ValueError names the known formats otherwise."""
    try:
        return READERS[name]
    except KeyError:
        raise ValueError(f"unknown format {name!r}; known: {sorted(READERS)}") from None
