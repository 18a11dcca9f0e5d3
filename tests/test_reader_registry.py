"""The reader registry is what ``convert`` and ``sray data convert`` read their formats, defaults and options from."""

from __future__ import annotations

import argparse
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

from sray.data_tools.readers.convert import ConvertConfig, convert_scene
from sray.data_tools.readers.registry import READERS, get_reader
from sray.jobs.data import convert as data_convert_cmd


@pytest.mark.parametrize("name", sorted(READERS))
def test_entry_matches_its_read_function(name: str) -> None:
    """The read function takes the shared keywords and every registered option; its defaults are the registry's."""
    reader = READERS[name]
    params = inspect.signature(reader.load()).parameters
    for keyword in ("name", "label_space", "size_hw", "frame_skip", "depth_scale", *(o.name for o in reader.options)):
        assert keyword in params, f"{name}: read function lacks {keyword!r}"
    assert params["size_hw"].default == reader.size_hw
    assert params["frame_skip"].default == reader.frame_skip


def test_unknown_format_and_foreign_option_are_refused(tmp_path: Path) -> None:
    """Errors name the known formats, and the options the chosen reader takes."""
    with pytest.raises(ValueError, match="known: \\['colmap', 'nerfstudio', 'replica', 'scannet', 'scannet-sens'\\]"):
        get_reader("polycam")
    cfg = ConvertConfig(format="replica", src=tmp_path / "seq", out=tmp_path / "ds", options={"tsv": tmp_path})
    with pytest.raises(ValueError, match="not inputs of the replica reader"):
        convert_scene(cfg)


def test_cli_takes_formats_and_reader_options_from_the_registry() -> None:
    """``--format`` choices are the registry's names; each reader option is a flag that reaches ConvertConfig."""
    parser = argparse.ArgumentParser()
    data_convert_cmd.register(parser.add_subparsers())
    convert = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices["convert"]
    fmt = next(a for a in convert._actions if a.dest == "format")
    assert tuple(fmt.choices) == tuple(READERS)
    flags = {s for a in convert._actions for s in a.option_strings}
    assert {f"--{o.name}" for r in READERS.values() for o in r.options} <= flags


def test_registry_and_convert_command_import_no_reader() -> None:
    """The convert command's parser reads the registry without importing a reader (no numpy, OpenCV, torch)."""
    heavy = ("numpy", "cv2", "torch", "sray.data_tools.readers.scannet", "sray.data_tools.readers.replica")
    code = f"import sys; import sray.jobs.data.convert; print(sorted(m for m in {heavy} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
