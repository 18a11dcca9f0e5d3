"""The import rules between folders (docs/architecture.md): ``model`` imports nothing of ours, ``data_tools`` no
model/platform/jobs, platform sub-packages import downwards, no module cycle, only ``platform/tracking/``
imports mlflow, and the wall: ``lab`` may import the product, nothing in the product imports ``lab``; files stay
short and narrow. Where imports sit is ``test_import_layout.py``."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from import_scan import LAB, PRODUCT, REPO, cycles, imported_modules, plant

FORBIDDEN = {
    "model": ("sray.data_tools", "sray.platform", "sray.jobs", "sray.lab"),
    "data_tools": ("sray.model", "sray.platform", "sray.jobs", "sray.lab"),
    "platform": ("sray.jobs", "sray.lab"),
    "jobs": ("sray.lab",),
}
"""Per folder: the sray packages its modules may not import (at module level or inside a function)."""


@pytest.mark.parametrize("folder", sorted(FORBIDDEN))
def test_folder_keeps_the_import_rule(folder: str) -> None:
    """No module under ``folder`` (sub-packages included) imports a package the rule forbids it."""
    files = sorted((REPO / folder).rglob("*.py"))
    assert files, folder
    broken = [f"{path.relative_to(REPO)} imports {name}" for path in files for name in imported_modules(path)
              if any(name == bad or name.startswith(bad + ".") for bad in FORBIDDEN[folder])]
    assert not broken, "\n".join(broken)


PLATFORM_LEVELS = {"common": 0, "config": 0, "checkpoints": 1, "tracking": 1, "viz": 1, "eval": 2, "train": 3,
                   "render": 3, "finetune": 4, "sweep": 4, "stability": 5, "cluster": 2, "migrate": 5, "label": 4}
"""docs/architecture.md: a ``platform`` sub-package imports only itself and sub-packages of a lower level."""

MAX_LINES = 300
"""No product file is longer than this (one job per file)."""


def _module_name(path: Path) -> str:
    return "sray." + ".".join(path.relative_to(REPO).with_suffix("").parts)


def _product_files() -> list[Path]:
    return sorted(p for folder in PRODUCT for p in (REPO / folder).rglob("*.py"))


def _lab_files() -> list[Path]:
    return sorted((REPO / LAB).rglob("*.py"))


def wall_violations(root: Path) -> list[str]:
    """Imports of ``sray.lab`` (or of the lab's top-level names) anywhere in the product folders under ``root``:
    module level, inside a function, absolute or relative."""
    broken = []
    for folder in PRODUCT:
        for path in sorted((root / folder).rglob("*.py")):
            broken += [f"{path.relative_to(root)} imports {name}" for name in imported_modules(path, root)
                       if name == "sray.lab" or name.startswith("sray.lab.")]
    return broken


def test_nothing_in_the_product_imports_the_lab() -> None:
    """The wall: the lab may import the product (it does), the product never imports the lab."""
    assert _lab_files(), "lab/ holds the studies and diagnostics"
    assert not wall_violations(REPO), "\n".join(["the product imports the lab (move the shared code into the "
                                                 "product, or the caller into lab/):", *wall_violations(REPO)])
    lab_imports = {n.split(".")[1] for p in _lab_files() for n in imported_modules(p) if n.startswith("sray.")}
    assert {"model", "platform", "lab"} <= lab_imports, lab_imports


def test_the_wall_scan_finds_a_breach(tmp_path: Path) -> None:
    """The scan is not vacuous: a product module importing the lab (absolutely, lazily or relatively) is reported,
    the lab importing the product is not."""
    planted = {"jobs/a.py": "from sray.lab.studies.spec import load_spec\n",
               "platform/eval/b.py": "def f():\n    import sray.lab.ceilings.measure\n",
               "jobs/bench/c.py": "from ...lab.cli import register\n",
               "lab/studies/d.py": "from sray.platform.sweep.engine import run_study\n", "model/e.py": "import sray\n"}
    plant(tmp_path, planted)
    assert sorted(wall_violations(tmp_path)) == [
        "jobs/a.py imports sray.lab.studies.spec", "jobs/a.py imports sray.lab.studies.spec.load_spec",
        "jobs/bench/c.py imports sray.lab.cli", "jobs/bench/c.py imports sray.lab.cli.register",
        "platform/eval/b.py imports sray.lab.ceilings.measure"]


def test_no_import_cycles_between_lab_modules() -> None:
    """The lab's own rule: its module import graph has no cycle either (a lab module and a product module cannot
    form one, since the product never imports the lab)."""
    known = {_module_name(p) for p in _lab_files()}
    graph = {_module_name(p): {n for n in imported_modules(p) if n in known} for p in _lab_files()}
    found = cycles(graph)
    assert not found, "\n".join(found)


def test_lab_files_stay_short() -> None:
    """The lab's own rule: one job per file there too, no lab file over ``MAX_LINES`` lines."""
    long = [f"{p.relative_to(REPO)}: {n}" for p in _lab_files() if (n := len(p.read_text().splitlines())) > MAX_LINES]
    assert not long, "\n".join(long)


def test_platform_subpackages_import_only_downwards() -> None:
    """Every platform sub-package has a level; imports between them point strictly downwards."""
    files = sorted((REPO / "platform").rglob("*.py"))
    packages = {p.relative_to(REPO / "platform").parts[0] for p in files}
    assert packages == set(PLATFORM_LEVELS), "give each new platform sub-package a level here and in docs"
    broken = []
    for path in files:
        own = path.relative_to(REPO / "platform").parts[0]
        for name in imported_modules(path):
            parts = name.split(".")
            if parts[:2] == ["sray", "platform"] and len(parts) > 2 and parts[2] != own:
                if PLATFORM_LEVELS[parts[2]] >= PLATFORM_LEVELS[own]:
                    broken.append(f"{path.relative_to(REPO)} ({own}) imports {name}")
    assert not broken, "\n".join(broken)


def test_no_import_cycles_between_product_modules() -> None:
    """The module import graph of the product (imports anywhere in a file) has no cycle."""
    files = _product_files()
    known = {_module_name(p) for p in files}
    graph = {_module_name(p): {n for n in imported_modules(p) if n in known} for p in files}
    found = cycles(graph)
    assert not found, "\n".join(found)


def test_model_imports_no_platform_library() -> None:
    """``model`` can be lifted into any project: no ray, mlflow, accelerate or webdataset."""
    banned = ("ray", "mlflow", "accelerate", "webdataset")
    broken = [f"{p.relative_to(REPO)} imports {n}" for p in sorted((REPO / "model").rglob("*.py"))
              for n in imported_modules(p) if n.split(".")[0] in banned]
    assert not broken, "\n".join(broken)


def test_product_files_stay_short() -> None:
    """One job per file: no product file over ``MAX_LINES`` lines."""
    long = [f"{p.relative_to(REPO)}: {n}" for p in _product_files()
            if (n := len(p.read_text().splitlines())) > MAX_LINES]
    assert not long, "\n".join(long)


MAX_LINE_CHARS = 120
"""Widest line allowed in any Python file of the repository, product and tests."""


def test_lines_stay_within_the_width() -> None:
    files = [*_product_files(), *_lab_files(), *sorted((REPO / "tests").rglob("*.py"))]
    wide = [f"{p.relative_to(REPO)}:{i}: {len(line)} characters" for p in files
            for i, line in enumerate(p.read_text().splitlines(), 1) if len(line) > MAX_LINE_CHARS]
    assert not wide, "\n".join(wide)


TRACKING = "platform/tracking"
"""The one folder whose modules may import mlflow (the MLflow tracker and its helpers)."""
TRACKER_INTERFACE = ("sray.platform.tracking.tracker", "sray.platform.tracking.registry",
                     "sray.platform.tracking.dashboard")
"""What code outside ``platform/tracking/`` may import from it: the interface, the registry, and the dashboard
behind ``sray ui``."""


def imported_names(path: Path) -> list[str]:
    """Every module a file imports, plus ``module.name`` for each ``from module import name``."""
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names += [node.module, *(f"{node.module}.{alias.name}" for alias in node.names)]
    return names


def tracking_violations(root: Path) -> list[str]:
    """Files of the product folders under ``root`` that import mlflow, or a tracking module other than
    the interface, from outside ``platform/tracking/``."""
    broken = []
    for folder in (*PRODUCT, LAB):
        for path in sorted((root / folder).rglob("*.py")):
            if (root / TRACKING) in path.parents:
                continue
            for name in imported_names(path):
                if name == "mlflow" or name.startswith("mlflow."):
                    broken.append(f"{path.relative_to(root)} imports {name}")
                elif name.startswith("sray.platform.tracking.") and not name.startswith(TRACKER_INTERFACE):
                    broken.append(f"{path.relative_to(root)} imports {name} (use the tracker interface)")
    return broken


def test_only_the_tracking_folder_imports_mlflow() -> None:
    """mlflow is imported only inside platform/tracking/; everything else talks to the tracker interface."""
    assert (REPO / TRACKING / "mlflow_tracker.py").is_file()
    assert not tracking_violations(REPO), "\n".join(tracking_violations(REPO))


def test_the_tracking_scan_finds_violations(tmp_path: Path) -> None:
    """The scan above is not vacuous: imports planted in a copy of the layout are reported, allowed ones not."""
    planted = {"jobs/a.py": "import mlflow.pytorch\n",
               "platform/eval/b.py": "def f():\n    from mlflow import MlflowClient\n",
               "model/c.py": "from sray.platform.tracking import logger\n",
               "platform/train/d.py": "from sray.platform.tracking.registry import get_tracker\n",
               "platform/tracking/e.py": "import mlflow\n", "data_tools/f.py": "import mlflowish\n"}
    plant(tmp_path, planted)
    assert sorted(tracking_violations(tmp_path)) == [
        "jobs/a.py imports mlflow.pytorch",
        "model/c.py imports sray.platform.tracking.logger (use the tracker interface)",
        "platform/eval/b.py imports mlflow", "platform/eval/b.py imports mlflow.MlflowClient"]
