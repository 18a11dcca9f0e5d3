"""``sray.data_tools.atomic``: whole files or nothing, and no temporary file left after a failure."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sray.data_tools import atomic
from sray.data_tools.atomic import TEMP_NAME, atomic_write_bytes, atomic_write_json, atomic_write_text


def test_writes_bytes_text_and_json(tmp_path: Path) -> None:
    """Each variant creates missing parent folders and leaves exactly the target file."""
    atomic_write_bytes(tmp_path / "a" / "b.bin", b"\x00\x01")
    atomic_write_text(tmp_path / "a" / "c.txt", "héllo\n")
    atomic_write_json(tmp_path / "a" / "d.json", {"k": [1, 2]})
    assert (tmp_path / "a" / "b.bin").read_bytes() == b"\x00\x01"
    assert (tmp_path / "a" / "c.txt").read_text(encoding="utf-8") == "héllo\n"
    assert json.loads((tmp_path / "a" / "d.json").read_text()) == {"k": [1, 2]}
    assert (tmp_path / "a" / "d.json").read_text().endswith("\n")
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["b.bin", "c.txt", "d.json"]


@pytest.mark.parametrize("fail_in", ["fsync", "replace"])
def test_failure_keeps_the_old_file_and_removes_the_temporary(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                              fail_in: str) -> None:
    """An error (or Ctrl-C) mid-write leaves the previous content and no temporary file."""
    target = tmp_path / "x.json"
    atomic_write_json(target, {"old": True})
    seen: list[str] = []

    def interrupt(*args: object) -> None:
        seen.extend(p.name for p in tmp_path.iterdir() if TEMP_NAME.match(p.name))
        raise KeyboardInterrupt("simulated")

    monkeypatch.setattr(atomic.os, fail_in, interrupt)
    with pytest.raises(KeyboardInterrupt):
        atomic_write_json(target, {"new": True})
    monkeypatch.undo()
    assert seen == [f".x.json.tmp{atomic.os.getpid()}"]  # the temporary existed, under the name TEMP_NAME matches
    assert [p.name for p in tmp_path.iterdir()] == ["x.json"]
    assert json.loads(target.read_text()) == {"old": True}


def test_replace_dir_swaps_a_whole_folder_in_and_removes_the_old_one(tmp_path: Path) -> None:
    from sray.data_tools.atomic import replace_dir

    target, aside = tmp_path / "scene", tmp_path / ".scene.old"
    for version in ("v1", "v2"):
        ready = tmp_path / f".ready-{version}"
        ready.mkdir()
        (ready / "a.txt").write_text(version)
        replace_dir(ready, target, aside)
        assert (target / "a.txt").read_text() == version and not ready.exists() and not aside.exists()
