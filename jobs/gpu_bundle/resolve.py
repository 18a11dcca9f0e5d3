"""Which wheels the GPU bundle holds: what the ``ray`` and ``fleet`` stages need, resolved by pip for the target, minus
the GPU image's packages and what sray never loads; versions from ``constraints.txt``, then this environment."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from .image import IMAGE_PACKAGES, normalise

ROOTS = ("ray[train]", "mlflow-skinny", "sqlalchemy", "alembic", "webdataset")
"""Ray Train, MLflow's client with its SQL store (SQLite tracking needs SQLAlchemy and Alembic), the shard loader."""
PIN_FROM = {"mlflow-skinny": "mlflow"}
"""Roots pinned to another constraint's version (released together)."""
LEFT_OUT = {"google-auth": "databricks-sdk's Google Cloud credentials, loaded only for Databricks on Google Cloud",
            "pyasn1": "needed only by google-auth", "pyasn1-modules": "needed only by google-auth"}
"""Declared dependencies sray never loads, left out for size (the bundle check proves the stages run without)."""
MANYLINUX_TAGS = ("manylinux_2_28_x86_64", "manylinux_2_27_x86_64", "manylinux_2_24_x86_64", "manylinux_2_17_x86_64",
                  "manylinux2014_x86_64", "manylinux1_x86_64", "linux_x86_64")
"""Platform tags the GPU machine (glibc >= 2.28, x86-64) installs; pip matches each tag exactly."""


class BundleError(RuntimeError):
    """The bundle cannot be built as asked; the message names the package and the fix."""


@dataclass(frozen=True)
class Pin:
    """One distribution of the resolved set: normalised name (PEP 503) and exact version."""

    name: str
    version: str

    def spec(self) -> str:
        """``name==version`` for pip."""
        return f"{self.name}=={self.version}"


def target_options(python_version: str) -> list[str]:
    """pip options selecting binary wheels for CPython ``python_version`` on manylinux x86-64."""
    options = ["--only-binary=:all:", "--python-version", python_version, "--implementation", "cp"]
    for tag in MANYLINUX_TAGS:
        options += ["--platform", tag]
    return options


def read_constraints(path: Path) -> dict[str, str]:
    """``name -> version`` of a constraints file's ``name==version`` lines; :class:`BundleError` on any other."""
    pins = {}
    for number, raw in enumerate(path.read_text().splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, version = line.partition("==")
        if not sep or not version.strip() or any(c in name for c in "<>=!~;[ "):
            raise BundleError(f"{path}:{number}: {raw!r} is not an exact pin; write it as name==version")
        pins[normalise(name)] = version.strip()
    return pins


def root_requirements(constraints: dict[str, str]) -> list[str]:
    """:data:`ROOTS` as requirements, each pinned to its (or its :data:`PIN_FROM`'s) ``constraints.txt`` version."""
    requirements = []
    for root in ROOTS:
        name = normalise(root.split("[", 1)[0])
        version = constraints.get(normalise(PIN_FROM.get(name, name)))
        requirements.append(f"{root}=={version}" if version else root)
    return requirements


def resolve(python_version: str, constraints_file: Path) -> list[Pin]:
    """Every distribution the roots need on CPython ``python_version`` (pip's resolver, metadata only), pinned by
    ``constraints_file``, then by this environment; :class:`BundleError` naming pip's complaint."""
    pip = [sys.executable, "-m", "pip"]
    constraints = read_constraints(constraints_file)
    with tempfile.TemporaryDirectory() as tmp:
        frozen = environment_constraints(Path(tmp) / "environment.txt", constraints)
        report = Path(tmp) / "report.json"
        done = subprocess.run([*pip, "install", "--dry-run", "--ignore-installed", "-q", "--report", str(report),
                               *target_options(python_version), "-c", str(constraints_file), "-c", str(frozen),
                               *root_requirements(constraints)], capture_output=True, text=True, check=False)
        if done.returncode != 0:  # pip's last lines, but its warnings about local indexes
            said = [line for line in done.stderr.splitlines() if line.strip() and "is ignored" not in line]
            raise BundleError(f"pip could not resolve {' '.join(ROOTS)} for CPython {python_version} on manylinux "
                              f"x86-64 with {constraints_file}: {' '.join(said[-3:]) or 'no message'}; fix the pin "
                              f"it names in {constraints_file.name} (or the environment's version) and build again")
        items = json.loads(report.read_text())["install"]
    return [Pin(normalise(i["metadata"]["name"]), i["metadata"]["version"]) for i in items]


def environment_constraints(path: Path, constraints: dict[str, str]) -> Path:
    """Write this environment's ``pip freeze`` pins (but editable ones and those ``constraints`` has) to ``path``."""
    freeze = subprocess.run([sys.executable, "-m", "pip", "freeze", "--exclude-editable"], capture_output=True,
                            text=True, check=True)
    path.write_text("\n".join(line for line in freeze.stdout.splitlines()
                              if "==" in line and normalise(line.split("==")[0]) not in constraints) + "\n")
    return path


def bundle_pins(resolved: list[Pin]) -> list[Pin]:
    """The resolved distributions the bundle carries: those the image lacks, less :data:`LEFT_OUT`, sorted."""
    return sorted((p for p in resolved if p.name not in IMAGE_PACKAGES and p.name not in LEFT_OUT),
                  key=lambda p: p.name)


def check_pins(pins: list[Pin], constraints: dict[str, str]) -> None:
    """:class:`BundleError` when a bundled version differs from its (or its :data:`PIN_FROM`'s) pin."""
    for pin in pins:
        wanted = constraints.get(normalise(PIN_FROM.get(pin.name, pin.name)))
        if wanted is not None and wanted != pin.version:
            raise BundleError(f"{pin.name} resolved to {pin.version} but constraints.txt pins "
                              f"{PIN_FROM.get(pin.name, pin.name)}=={wanted}: build again from an environment "
                              "installed with PIP_CONSTRAINT=constraints.txt")
