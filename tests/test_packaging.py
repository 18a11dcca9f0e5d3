"""The layout rule: the repo's folders live under ``sray.*`` and never shadow the stdlib; ``sray.load`` exists in
every way sray is imported (editable install, repo root on sys.path, wheel, Ray working_dir copy)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import sray
from sray.platform.label.labeller import load

REPO = Path(__file__).resolve().parents[1]


def test_import_sray_platform_then_torch_from_repo_root() -> None:
    """From the repo root (on sys.path first), ``platform`` is still the stdlib module."""
    code = (
        "import sys; sys.path.insert(0, '.'); "
        "import sray.platform, torch, platform; "
        "assert platform.system(), 'stdlib platform broken'; "
        "assert platform.__file__.startswith(sys.base_prefix) or 'lib/python' in platform.__file__, platform.__file__; "
        "import sray.model, sray.data_tools, sray.jobs; print(platform.__file__)"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "platform.py" in out.stdout and str(REPO / "platform") not in out.stdout


def test_no_init_in_top_level_folders() -> None:
    """No ``__init__.py`` in the mapped folders (ARCHITECTURE §1): the product's four and the lab."""
    for folder in ("platform", "model", "jobs", "data_tools", "lab"):
        assert not (REPO / folder / "__init__.py").exists(), folder


def test_cli_help_lists_subcommands() -> None:
    """The console script parses and lists its subcommands."""
    from sray.jobs.cli import build_parser

    help_text = build_parser().format_help()
    for name in ("data", "bench"):
        assert name in help_text


IMPORT_CHECK = (
    "import sys; "
    "sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in getattr(f, '__module__', '')] "
    "if {drop_editable} else sys.meta_path; "
    "sys.path.insert(0, {first!r}) if {first!r} else None; "
    "import importlib.util, sray, sray.model, sray.data_tools.scene, platform; "
    "assert 'torch' not in sys.modules, 'import sray pulled in torch'; "
    "api = importlib.util.find_spec('sray.platform.label.labeller').origin; "
    "assert platform.system() and api == str(sray.model.__path__[0]).replace('model', 'platform/label/labeller.py'); "
    "print(sray.__file__); print(list(sray.model.__path__)[0])"
)
"""Imports ``sray`` and mapped folders, finds the module ``sray.load`` comes from beside them (optionally with the
editable install's finder removed and a folder first on sys.path), prints where ``sray`` and ``sray.model`` came
from. Torch is never imported, so each run takes a fraction of a second."""


def run_import_check(cwd: Path, first: str = "", drop_editable: bool = False) -> list[str]:
    """The two paths :data:`IMPORT_CHECK` prints, run in a fresh interpreter from ``cwd``."""
    code = IMPORT_CHECK.format(first=first, drop_editable=drop_editable)
    out = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.split()


def test_sray_load_is_the_labeller_loader() -> None:
    """``sray.load`` is :func:`sray.platform.label.labeller.load`, resolved on first use; other names are refused."""
    assert sray.load is load
    with pytest.raises(AttributeError, match="no attribute 'loads'"):
        sray.loads  # noqa: B018


def test_sray_load_exists_from_the_editable_install_and_from_the_repo_root(tmp_path: Path) -> None:
    """``sray`` is a regular package (``sray/__init__.py``) and still finds the four folders: editable install from
    any folder, and the repo root first on sys.path (an interactive shell, ``python -m``, pytest)."""
    assert run_import_check(tmp_path) == [str(REPO / "sray" / "__init__.py"), str(REPO / "model")]
    assert run_import_check(REPO, first=".") == [str(REPO / "sray" / "__init__.py"), str(REPO / "model")]


def test_sray_load_exists_in_a_wheel_and_in_a_ray_working_dir_copy(tmp_path: Path) -> None:
    """A wheel holds the folders inside ``sray/``; a Ray ``working_dir`` copy of the checkout (its root first on
    sys.path, no install) finds them beside it. Neither reads the checkout."""
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", str(REPO), "--no-deps", "--no-build-isolation",
                            "-q", "-w", str(tmp_path / "dist")], capture_output=True, text=True, timeout=300)
    assert built.returncode == 0, built.stderr
    (wheel,) = (tmp_path / "dist").glob("sray-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        archive.extractall(tmp_path / "site")
    assert not (tmp_path / "site" / "platform").exists()  # nothing but sray/ at the top: the stdlib stays
    site = run_import_check(tmp_path, first=str(tmp_path / "site"), drop_editable=True)
    assert site == [str(tmp_path / "site" / "sray" / "__init__.py"), str(tmp_path / "site" / "sray" / "model")]
    copy = tmp_path / "working_dir"
    for folder in ("sray", "model", "data_tools", "platform", "jobs"):
        shutil.copytree(REPO / folder, copy / folder, ignore=shutil.ignore_patterns("__pycache__"))
    assert run_import_check(copy, first=".", drop_editable=True) == [str(copy / "sray" / "__init__.py"),
                                                                      str(copy / "model")]
