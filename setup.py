"""Map the top-level folders into the one ``sray`` namespace.

``platform/``, ``model/``, ``jobs/``, ``data_tools/`` and ``lab/`` carry no ``__init__.py`` so that the
standard-library ``platform`` module is never shadowed from the repo root; each folder (and every
sub-folder) is installed as ``sray.<folder>``. Metadata and dependencies live in pyproject.toml.
"""

from setuptools import find_namespace_packages, setup

FOLDERS = ("model", "data_tools", "platform", "jobs", "lab")

# sray/ is the package itself (its __init__.py: the Python API, sray.load); in a wheel the folders land inside
# it, in an editable install its __init__.py finds them beside it (tests/test_packaging.py).
packages: list[str] = ["sray"]
package_dir: dict[str, str] = {"sray": "sray"}
for folder in FOLDERS:
    for sub in [folder, *(f"{folder}.{p}" for p in find_namespace_packages(where=folder))]:
        if "__pycache__" in sub:
            continue
        packages.append(f"sray.{sub}")
        package_dir[f"sray.{sub}"] = sub.replace(".", "/")

setup(packages=packages, package_dir=package_dir)
