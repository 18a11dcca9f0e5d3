"""The import rules (docs/architecture.md): ``model`` imports nothing of ours, ``data_tools`` no model/platform/jobs,
only ``platform/tracking/`` imports mlflow, imports sit at the top of a module (lazy ones only in a command's entry
function and in the allow-listed optional paths), and the folders of ``data_tools`` and ``jobs`` import one way."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FORBIDDEN = {
    "model": ("sray.data_tools", "sray.platform", "sray.jobs"),
    "data_tools": ("sray.model", "sray.platform", "sray.jobs"),
}
"""Per folder: the sray packages its modules may not import (at module level or inside a function)."""


def imported_modules(path: Path, root: Path = REPO) -> list[str]:
    """Absolute module names a Python file under ``root`` imports anywhere in it (relative imports resolved;
    ``from package import name`` also counts ``package.name``, which may be a module)."""
    names = []
    package = ["sray", *path.relative_to(root).parent.parts]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else [])) \
                if node.level else node.module
            names += [base, *(f"{base}.{alias.name}" for alias in node.names)]
    return names


@pytest.mark.parametrize("folder", sorted(FORBIDDEN))
def test_folder_keeps_the_import_rule(folder: str) -> None:
    """No module under ``folder`` (sub-packages included) imports a package the rule forbids it."""
    files = sorted((REPO / folder).rglob("*.py"))
    assert files, folder
    broken = [f"{path.relative_to(REPO)} imports {name}" for path in files for name in imported_modules(path)
              if any(name == bad or name.startswith(bad + ".") for bad in FORBIDDEN[folder])]
    assert not broken, "\n".join(broken)


PRODUCT = ("model", "data_tools", "platform", "jobs")
"""The four top-level folders installed as ``sray.<folder>``."""

PLATFORM_LEVELS = {"common": 0, "config": 0, "checkpoints": 1, "tracking": 1, "viz": 1, "eval": 2, "train": 3,
                   "render": 3, "finetune": 4, "sweep": 4, "stability": 5, "cluster": 2}
"""docs/architecture.md: a ``platform`` sub-package imports only itself and sub-packages of a lower level."""

MAX_LINES = 300
"""No product file is longer than this (one job per file)."""


def _module_name(path: Path) -> str:
    return "sray." + ".".join(path.relative_to(REPO).with_suffix("").parts)


def _product_files() -> list[Path]:
    return sorted(p for folder in PRODUCT for p in (REPO / folder).rglob("*.py"))


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
    state: dict[str, int] = {}
    cycles: list[str] = []

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(" -> ".join(trail[trail.index(nxt):] + [node, nxt]) if nxt in trail
                              else f"{node} -> {nxt}")
            elif nxt not in state:
                visit(nxt, trail + [node])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    assert not cycles, "\n".join(cycles)


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
    files = [*_product_files(), *sorted((REPO / "tests").rglob("*.py"))]
    wide = [f"{p.relative_to(REPO)}:{i}: {len(line)} characters" for p in files
            for i, line in enumerate(p.read_text().splitlines(), 1) if len(line) > MAX_LINE_CHARS]
    assert not wide, "\n".join(wide)


TRACKING = "platform/tracking"
"""The one folder whose modules may import mlflow (the MLflow tracker and its helpers)."""
TRACKER_INTERFACE = ("sray.platform.tracking.tracker", "sray.platform.tracking.registry",
                     "sray.platform.tracking.fleet_parent_run", "sray.platform.tracking.dashboard")
"""What code outside ``platform/tracking/`` may import from it: the interface, the registry, the fleet's
parent-run helper (written against the interface), and the dashboard behind ``sray ui``."""


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
    for folder in ("model", "data_tools", "platform", "jobs"):
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
    for name, text in planted.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    assert sorted(tracking_violations(tmp_path)) == [
        "jobs/a.py imports mlflow.pytorch",
        "model/c.py imports sray.platform.tracking.logger (use the tracker interface)",
        "platform/eval/b.py imports mlflow", "platform/eval/b.py imports mlflow.MlflowClient"]


LAZY_IMPORTS_ALLOWED = {
    "data_tools/readers/registry.py":
        "reader plug-ins: `sray data convert` builds its parser from the registry without numpy or OpenCV; a "
        "reader's module is imported when its format is converted (tests/test_reader_registry.py)",
    "platform/finetune/methods/sray_method.py":
        "method plug-ins: the CLI reads the method registry without torch; a method imports its learner and "
        "artifact loader when it is built or loaded (tests/test_recipe_method.py)",
    "platform/finetune/methods/semantic_nerf_method.py":
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
    "jobs/gpu_check/stage_training.py":
        "accelerate: the stage skips where it is not installed",
}
"""Files (under the repository root) allowed imports inside functions, each with the reason. Anywhere else an
import inside a function fails :func:`test_imports_sit_at_the_top_of_their_module`, except in the entry function of
a command module (:func:`command_entry_points`)."""


def command_entry_points(root: Path) -> dict[str, set[str]]:
    """File (relative to ``root``) -> names of its entry functions, for every command module: the modules
    ``jobs/cli.py`` and ``jobs/data/command.py`` register, their functions passed as ``set_defaults(func=...)``.
    Their imports may wait for the command to run, so that ``sray --help`` stays fast."""
    modules = []
    for path, name in (("jobs/cli.py", "SUBCOMMAND_MODULES"), ("jobs/data/command.py", "DATA_SUBCOMMAND_MODULES")):
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
    """Imports inside functions of the product folders under ``root`` outside ``allowed`` files and command entry
    functions."""
    entries = command_entry_points(root)
    broken = []
    for path in sorted(p for folder in PRODUCT for p in (root / folder).rglob("*.py")):
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
    assert entries["jobs/train_cmd.py"] == {"_train"} and entries["jobs/data/stats.py"] == {"_run"}, entries


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
    for name, text in planted.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    assert lazy_import_violations(tmp_path, {"platform/b.py": "optional"}) == [
        "jobs/x_cmd.py:10 imports mlflow inside helper()", "model/c.py:9 imports torch inside m()",
        "platform/a.py:5 imports ray inside f()", "platform/a.py:8 imports .b inside f.g()"]


FOLDER_GRAPHS = ("data_tools", "jobs")
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


def cycles(graph: dict[str, set[str]]) -> list[str]:
    """Each cycle of ``graph`` found by a depth-first walk, as ``a -> b -> a``."""
    found: list[str] = []
    state: dict[str, int] = {}

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                found.append(" -> ".join(trail[trail.index(nxt):] + [node, nxt]) if nxt in trail
                             else f"{node} -> {nxt}")
            elif nxt not in state:
                visit(nxt, trail + [node])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    return found


@pytest.mark.parametrize("folder", FOLDER_GRAPHS)
def test_the_parts_of_a_folder_import_one_way(folder: str) -> None:
    """``data_tools``: its top-level modules import no sub-folder, the sub-folders import each other without a loop.
    ``jobs``: the top-level command modules import the sub-packages (``bench`` and the rest), never the reverse."""
    graph = folder_graph(REPO, folder)
    assert len(graph) > 3, graph
    assert not cycles(graph), f"{folder}: " + "; ".join(cycles(graph))


def test_the_folder_scan_finds_a_loop(tmp_path: Path) -> None:
    """A top-level module and a sub-folder importing each other (absolutely or relatively) make a loop."""
    planted = {"jobs/a_cmd.py": "from sray.jobs.bench.doc import record\n",
               "jobs/bench/doc.py": "from ..recipes import get_recipe\n", "jobs/recipes.py": "import json\n"}
    for name, text in planted.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    assert cycles(folder_graph(tmp_path, "jobs")) == [". -> bench -> ."]
