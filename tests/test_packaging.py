"""The layout rule: the repo's folders live under ``sray.*`` and never shadow the stdlib."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

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
