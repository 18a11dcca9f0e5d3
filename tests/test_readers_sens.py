"""The raw ScanNet reader (``<scan>.sens`` + label zip) against the exported-frames reader on the same content,
through the registry and the ``sray data convert`` / ``sray data check`` CLI, and its errors."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sens_writer import pack_sens  # noqa: E402
from source_writers import write_scannet_export  # noqa: E402
from test_readers import H, W, random_scene, write_tsv  # noqa: E402

from sray.data_tools.readers.scannet import read_scannet  # noqa: E402
from sray.data_tools.readers.scannet_sens import read_scannet_sens  # noqa: E402


@pytest.fixture
def scan(tmp_path: Path) -> tuple[Path, Path, Path]:
    """(export folder, raw scan folder, tsv) holding the same 8 frames; frame 2's pose is invalid and frame 5
    has no label image."""
    tsv = write_tsv(tmp_path / "labels.tsv")
    export = write_scannet_export(random_scene(7, n_views=8), tmp_path / "export", tsv)
    pack_sens(export, tmp_path / "scene0000_00", "scene0000_00", invalid_pose_frames=(2,), unlabelled_frames=(5,))
    return export, tmp_path / "scene0000_00", tsv


@pytest.mark.parametrize("size_hw, frame_skip", [((H, W), 1), ((H // 2, W // 2), 2)])
def test_raw_scan_reads_as_the_export_of_the_same_content(scan, size_hw, frame_skip) -> None:
    export, raw, tsv = scan
    a = read_scannet(export, "s", tsv=tsv, size_hw=size_hw, frame_skip=frame_skip)
    b = read_scannet_sens(raw, "s", tsv=tsv, size_hw=size_hw, frame_skip=frame_skip, progress=False)
    assert a.meta.view_ids == b.meta.view_ids and "000002" not in b.meta.view_ids and "000005" not in b.meta.view_ids
    assert sorted(a.meta.extra["dropped_frames"]) == sorted(b.meta.extra["dropped_frames"]) == ["2", "5"]
    for x, y in zip(a.views(), b.views()):
        np.testing.assert_array_equal(y.rgb, x.rgb)
        np.testing.assert_array_equal(y.label, x.label)
        np.testing.assert_array_equal(y.depth, x.depth)
        np.testing.assert_allclose(y.K, x.K, rtol=0, atol=1e-6)
        np.testing.assert_allclose(y.c2w, x.c2w, rtol=0, atol=1e-6)


def test_convert_and_check_a_raw_scan_through_the_cli(scan, tmp_path, capsys) -> None:
    from sray.jobs.cli import main

    _, raw, tsv = scan
    assert main(["data", "convert", "--format", "scannet-sens", str(raw), "--out", str(tmp_path / "ds"),
                 "--tsv", str(tsv), "--size", f"{W}x{H}", "--frame-skip", "1", "--holdout-every", "0"]) == 0
    assert main(["data", "check", str(tmp_path / "ds")]) == 0
    scene_json = next((tmp_path / "ds").glob("*/scene.json")).read_text()
    assert '"source_format": "scannet-sens"' in scene_json


def test_truncated_or_foreign_files_are_clear_errors(scan, tmp_path) -> None:
    _, raw, tsv = scan
    sens = raw / "scene0000_00.sens"
    data = sens.read_bytes()
    sens.write_bytes(data[:-100])
    with pytest.raises(ValueError, match=r"scene0000_00\.sens: file ends inside frame 7's images; .*truncated"):
        read_scannet_sens(raw, "s", tsv=tsv, progress=False)
    sens.write_bytes(data[:40])
    with pytest.raises(ValueError, match=r"file ends inside the calibration matrices"):
        read_scannet_sens(raw, "s", tsv=tsv, progress=False)
    sens.write_bytes(b"\x05\x00\x00\x00" + data[4:])
    with pytest.raises(ValueError, match="version 5; this reader reads version 4"):
        read_scannet_sens(raw, "s", tsv=tsv, progress=False)
    sens.write_bytes(data)
    (raw / "scene0000_00_2d-label-filt.zip").unlink()
    with pytest.raises(FileNotFoundError, match="_2d-label-filt.zip"):
        read_scannet_sens(raw, "s", tsv=tsv, progress=False)
