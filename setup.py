"""Map the top-level folders into the one ``sray`` namespace.

``platform/``, ``model/``, ``jobs/``, ``data_tools/`` and ``lab/`` carry no ``__init__.py`` so that the
standard-library ``platform`` module is never shadowed from the repo root; each folder (and every
sub-folder) is installed as ``sray.<folder>``. Metadata and dependencies live in pyproject.toml.
"""

from setuptools import find_namespace_packages, setup

FOLDERS = ("model", "data_tools", "platform", "jobs", "lab")

packages: list[str] = []
package_dir: dict[str, str] = {}
for folder in FOLDERS:
    for sub in [folder, *(f"{folder}.{p}" for p in find_namespace_packages(where=folder))]:
        if "__pycache__" in sub:
            continue
        packages.append(f"sray.{sub}")
        package_dir[f"sray.{sub}"] = sub.replace(".", "/")

setup(packages=packages, package_dir=package_dir)
