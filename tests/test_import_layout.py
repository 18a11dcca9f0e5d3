"""Where imports sit (docs/architecture.md): at the top of their module, lazy ones only in a command's entry
function and in the allow-listed optional paths; and the parts of ``data_tools`` and ``jobs`` import one way."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from import_scan import LAB, PRODUCT, REPO, cycles, imported_modules, plant

LAZY_IMPORTS_ALLOWED = {
    "platform/finetune/methods/sray_method.py":
        "method plug-ins: the CLI reads the method registry without torch; a method imports its learner and "
        "artifact loader when it is built or loaded (tests/test_recipe_method.py)",
    "platform/finetune/methods/semantic_nerf_method.py":
        "method plug-ins: as sray_method.py",
    "platform/finetune/methods/transfer_method.py":
        "method plug-ins: as sray_method.py",
    "platform/finetune/methods/sray_rgbd_method.py":
        "method plug-ins: as sray_method.py",
    "platform/common/ray_address.py":
        "the GCS request imports Ray only once a TCP connection to the address succeeded: `sray train` refuses a "
        "bad input with Ray never imported (tests/test_train_inputs.py)",
    "platform/tracking/mlflow_tracker.py":
        "mlflow (absent from the GPU image, seconds to import) is imported when a store is used: choosing a "
        "tracker by name, the run links and `sray --help` go without it",
    "platform/tracking/runs.py":
        "mlflow on use: as mlflow_tracker.py",
    "platform/tracking/dashboard.py":
        "mlflow on use: as mlflow_tracker.py (`sray ui` reads the dashboard's port at parser time)",
    "jobs/gpu_check/stage_ray.py":
        "Ray, MLflow and webdataset, which the GPU image may lack: the stage checks for them and skips, so "
        "`sray gpu-check` starts with torch and accelerate alone (docs/gpu.md)",
    "jobs/gpu_check/stage_fleet.py":
        "the finetune fleet needs Ray, MLflow and webdataset: as stage_ray.py",
    "jobs/gpu_check/stage_minutes.py":
        "the GPU-minutes recipe's training and scoring need Ray, MLflow and webdataset: as stage_ray.py",
    "jobs/gpu_check/stage_training.py":
        "accelerate: the stage skips where it is not installed",
}
"""Files (under the repository root) allowed imports inside functions, each with the reason. Anywhere else an
import inside a function fails :func:`test_imports_sit_at_the_top_of_their_module`, except in the entry function of
a command module (:func:`command_entry_points`)."""


def command_entry_points(root: Path) -> dict[str, set[str]]:
    """File (relative to ``root``) -> names of its entry functions, for every command module: the modules
    ``jobs/cli.py``, ``jobs/data/command.py`` and the lab's ``lab/cli.py`` register, their
    functions passed as ``set_defaults(func=...)``.
    Their imports may wait for the command to run, so that ``sray --help`` stays fast."""
    modules = []
    for path, name in (("jobs/cli.py", "SUBCOMMAND_MODULES"), ("jobs/data/command.py", "DATA_SUBCOMMAND_MODULES"),
                       ("lab/cli.py", "LAB_COMMAND_MODULES")):
        if (root / path).is_file():
            for node in ast.parse((root / path).read_text()).body:
                if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == name for t in node.targets):
                    modules += ast.literal_eval(node.value)
    entries = {}
    for module in modules:
        path = "/".join(module.split(".")[1:]) + ".py"
        calls = [n for n in ast.walk(ast.parse((root / path).read_text())) if isinstance(n, ast.Call)
                 and isinstance(n.func, ast.Attribute) and n.func.attr == "set_defaults"]
        entries[path] = {k.value.id for c in calls for k in c.keywords
                         if k.arg == "func" and isinstance(k.value, ast.Name)}
    return entries


def function_imports(path: Path) -> list[tuple[str, int, str]]:
    """(enclosing function, line, imported module) of every import inside a function (method, nested function)."""
    found = []

    def visit(node: ast.AST, function: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                visit(child, child.name if not function else f"{function}.{child.name}")
            elif isinstance(child, (ast.Import, ast.ImportFrom)) and function:
                names = [a.name for a in child.names] if isinstance(child, ast.Import) else \
                    ["." * child.level + (child.module or "")]
                found.extend((function, child.lineno, name) for name in names)
            else:
                visit(child, function)

    visit(ast.parse(path.read_text(), str(path)), "")
    return found


def lazy_import_violations(root: Path, allowed: dict[str, str]) -> list[str]:
    """Imports inside functions of the product folders and the lab under ``root`` outside ``allowed`` files and
    command entry functions."""
    entries = command_entry_points(root)
    broken = []
    for path in sorted(p for folder in (*PRODUCT, LAB) for p in (root / folder).rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel in allowed:
            continue
        broken += [f"{rel}:{line} imports {name} inside {function}()"
                   for function, line, name in function_imports(path) if function not in entries.get(rel, ())]
    return broken


def test_imports_sit_at_the_top_of_their_module() -> None:
    """Every import is at module level, except in a command's entry function and in the allow-listed files."""
    assert not lazy_import_violations(REPO, LAZY_IMPORTS_ALLOWED), "\n".join(
        ["move these imports to the top of their module (or justify one in LAZY_IMPORTS_ALLOWED):",
         *lazy_import_violations(REPO, LAZY_IMPORTS_ALLOWED)])


def test_every_allowed_lazy_import_is_still_needed() -> None:
    """Each allow-listed file exists, has a reason and still imports inside a function; the scan finds the command
    modules' entry functions."""
    stale = [rel for rel, reason in LAZY_IMPORTS_ALLOWED.items()
             if not reason.strip() or not (REPO / rel).is_file() or not function_imports(REPO / rel)]
    assert not stale, f"drop these from LAZY_IMPORTS_ALLOWED: {stale}"
    entries = command_entry_points(REPO)
    assert entries["jobs/train_cmd.py"] == {"_train"} and entries["jobs/data/convert.py"] == {"run"}, entries


def test_the_lazy_import_scan_finds_violations(tmp_path: Path) -> None:
    """The scan is not vacuous: imports planted in functions of a copy of the layout are reported, unless they sit
    in a command's entry function or an allowed file; module-level ones (``TYPE_CHECKING`` included) never are."""
    planted = {"jobs/cli.py": 'SUBCOMMAND_MODULES = ("sray.jobs.x_cmd",)\n',
               "jobs/x_cmd.py": "def register(sub):\n    sub.set_defaults(func=run)\n\n\ndef run(args):\n"
                                "    import ray\n\n\ndef helper():\n    import mlflow\n",
               "platform/a.py": "import os\n\n\ndef f():\n    import ray\n\n    def g():\n        from .b import x\n",
               "platform/b.py": "def f():\n    import webdataset\n",
               "model/c.py": "from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    import torch\n\n\n"
                             "class C:\n    def m(self):\n        import torch\n"}
    plant(tmp_path, planted)
    assert lazy_import_violations(tmp_path, {"platform/b.py": "optional"}) == [
        "jobs/x_cmd.py:10 imports mlflow inside helper()", "model/c.py:9 imports torch inside m()",
        "platform/a.py:5 imports ray inside f()", "platform/a.py:8 imports .b inside f.g()"]


FOLDER_GRAPHS = ("data_tools", "jobs", "lab")
"""Folders whose parts import one way: the modules directly in the folder count as one part, each sub-folder as
another, and the graph of imports between the parts has no cycle."""


def folder_graph(root: Path, folder: str) -> dict[str, set[str]]:
    """Part -> parts it imports (anywhere in a file), for the parts of ``folder``: ``.`` for its top-level modules,
    a sub-folder's name for the modules under it."""
    def part(module: str) -> str | None:
        parts = module.split(".")
        if parts[:2] != ["sray", folder] or len(parts) < 3:
            return None
        return parts[2] if (root / folder / parts[2]).is_dir() else "."

    graph: dict[str, set[str]] = {}
    for path in (root / folder).rglob("*.py"):
        rel = path.relative_to(root / folder).parts
        own = rel[0] if len(rel) > 1 else "."
        graph.setdefault(own, set()).update(p for n in imported_modules(path, root)
                                            if (p := part(n)) not in (None, own))
    return graph


@pytest.mark.parametrize("folder", FOLDER_GRAPHS)
def test_the_parts_of_a_folder_import_one_way(folder: str) -> None:
    """``data_tools``: its top-level modules import no sub-folder, the sub-folders import each other without a loop.
    ``jobs``: the top-level command modules import the sub-packages (``bench`` and the rest), never the reverse.
    ``lab``: its sub-folders by concern (``studies``, ``accuracy``, ``ceilings``, …) import each other without a loop,
    and only ``cli.py`` at its top imports them."""
    graph = folder_graph(REPO, folder)
    assert len(graph) > 3, graph
    assert not cycles(graph), f"{folder}: " + "; ".join(cycles(graph))


def test_the_folder_scan_finds_a_loop(tmp_path: Path) -> None:
    """A top-level module and a sub-folder importing each other (absolutely or relatively) make a loop."""
    planted = {"jobs/a_cmd.py": "from sray.jobs.bench.report import record\n",
               "jobs/bench/report.py": "from ..recipes import get_recipe\n", "jobs/recipes.py": "import json\n"}
    plant(tmp_path, planted)
    assert cycles(folder_graph(tmp_path, "jobs")) == [". -> bench -> ."]
