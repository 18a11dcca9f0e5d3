"""CONTRIBUTING.md, "Add a dataset format", performed on a toy format: one ``.npz`` file per frame.

The recipe is two edits in ``data_tools/readers/``: a read function returning a canonical ``Scene``
and one ``Reader`` entry in the registry. Here both live in the test (the entry is added for the
test's duration only); then ``sray data convert`` and ``sray data check`` run through the real CLI.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_readers_convert import plane_scene

from sray.data_tools.label_spaces import class_names
from sray.data_tools.readers.registry import READERS, Reader
from sray.data_tools.scene import Scene, SceneMeta, View
from sray.data_tools.scene_folder import read_scene
from sray.jobs.cli import main


def read_npz_frames(src: Path, *, name: str, label_space: str, size_hw: tuple[int, int] | None,
                    frame_skip: int, depth_scale: float) -> Scene:
    """The toy reader: ``SRC/frame_<id>.npz`` holding rgb, depth (metres), label, K and c2w (OpenCV)."""
    ids = [p.stem.removeprefix("frame_") for p in sorted(src.glob("frame_*.npz"))][::frame_skip]

    def read_view(view_id: str) -> View:
        with np.load(src / f"frame_{view_id}.npz") as f:
            return View(view_id, f["rgb"], f["depth"], f["label"], f["K"], f["c2w"])

    return Scene(SceneMeta(name, label_space, class_names(label_space), ids, {}), read_view)


def write_npz_frames(scene: Scene, dst: Path) -> Path:
    """Write ``scene`` in the toy format, frames numbered in capture order (what a user's exporter writes)."""
    dst.mkdir(parents=True)
    for i, v in enumerate(scene.views()):
        np.savez(dst / f"frame_{i:04d}.npz", rgb=v.rgb, depth=v.depth, label=v.label, K=v.K, c2w=v.c2w)
    return dst


def test_a_new_format_converts_and_checks_through_the_cli(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(READERS, "npz-frames", Reader(name="npz-frames", summary="one .npz per frame (toy)",
                                                      load=lambda: read_npz_frames, size_hw=None, frame_skip=1))
    source = plane_scene(20)
    src = write_npz_frames(source, tmp_path / "capture")
    out = tmp_path / "dataset"
    assert main(["data", "convert", str(src), "--format", "npz-frames", "--out", str(out), "--role", "test"]) == 0
    assert main(["data", "check", str(out)]) == 0
    written = read_scene(out / "capture")
    assert written.meta.splits["source"] and written.meta.splits["test"]
    assert written.meta.near < 2.0 < written.meta.far  # the wall is 2 m away in every view
    assert written.meta.view_ids == [f"{i:04d}" for i in range(20)]
    for i, view_id in enumerate(written.meta.view_ids):
        got, want = written.read_view(view_id), source.read_view(f"v{i}")
        np.testing.assert_array_equal(got.rgb, want.rgb)
        np.testing.assert_array_equal(got.label, want.label)
        np.testing.assert_allclose(got.c2w, want.c2w, atol=1e-6)
        np.testing.assert_allclose(got.K, want.K, atol=1e-6)
