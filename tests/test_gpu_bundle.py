"""``sray gpu-bundle``'s parts on tiny fake wheels: a repacked wheel keeps a valid RECORD (checked by the ``wheel``
package) and installs with pip without the dropped folders; pins follow constraints.txt; an over-weight bundle and
a missing wheel are refused with the package and the fix, leaving the previous bundle untouched. The whole chain
(resolve, download, install offline, run the stages) is ``make gpu-bundle-check``, too slow for the suite."""

from __future__ import annotations

import base64
import hashlib
import json
import os
import shutil
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from wheel.wheelfile import WheelFile

from sray.jobs.gpu_bundle.build import DROP, STRIP, BundleError, Pin, assemble, download
from sray.jobs.gpu_bundle.resolve import bundle_pins, check_pins, read_constraints, root_requirements
from sray.jobs.gpu_bundle.wheel_strip import strip_wheel

REPO = Path(__file__).resolve().parents[1]


def fake_wheel(folder: Path, name: str, version: str, files: dict[str, bytes], scripts: str = "") -> Path:
    """A minimal valid wheel of ``name`` holding ``files`` (ELF files and ``*/bin/*`` paths executable), with its
    RECORD."""
    info = f"{name}-{version}.dist-info"
    files = {**files, f"{info}/METADATA": f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n".encode(),
             f"{info}/WHEEL": b"Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\nTag: py3-none-any\n"}
    if scripts:
        files[f"{info}/entry_points.txt"] = scripts.encode()
    record = [f"{p},sha256={base64.urlsafe_b64encode(hashlib.sha256(d).digest()).rstrip(b'=').decode()},{len(d)}"
              for p, d in files.items()]
    path = folder / f"{name}-{version}-py3-none-any.whl"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for p, data in files.items():
            entry = zipfile.ZipInfo(p)
            entry.external_attr = (stat.S_IFREG | (0o755 if "/bin/" in p or data[:4] == b"\x7fELF" else 0o644)) << 16
            z.writestr(entry, data)
        z.writestr(f"{info}/RECORD", "\n".join(record + [f"{info}/RECORD,,"]) + "\n")
    return path


ELF = Path(shutil.which("true") or "/bin/true").resolve().read_bytes()
"""A small real ELF executable (``true``) standing in for Ray's native binaries."""


def fake_ray(folder: Path) -> Path:
    """A fake ``ray`` wheel holding every folder :data:`DROP` leaves out, the binaries :data:`STRIP` names (copies
    of ``true``), a kept executable and two scripts."""
    files = {f"{prefix}payload.bin": os.urandom(4096) for prefix in DROP["ray"]}
    files |= {binary: ELF for binary in STRIP["ray"]}
    files |= {"ray/__init__.py": b"VERSION = '2.60.0'\n", "ray/core/bin/gcs_server": b"#!/bin/sh\necho gcs\n"}
    scripts = "[console_scripts]\nray = ray.scripts.scripts:main\nrllib = ray.rllib.scripts:cli\n"
    return fake_wheel(folder, "ray", "2.60.0", files, scripts)


def test_a_stripped_wheel_has_a_valid_record_and_installs_without_the_dropped_folders(tmp_path: Path) -> None:
    src = fake_ray(tmp_path)
    (tmp_path / "out").mkdir()
    done = strip_wheel(src, tmp_path / "out", DROP["ray"], STRIP["ray"])
    assert done.dropped_files == len(DROP["ray"]) and done.dropped_bytes >= 4096 * len(DROP["ray"])
    with WheelFile(done.path) as wf:  # the wheel package checks every file against its RECORD line as it reads
        names = [n for n in wf.namelist() if not n.endswith("/")]
        for name in names:
            wf.read(name)
        record = wf.read("ray-2.60.0.dist-info/RECORD").decode().splitlines()
        scripts = wf.read("ray-2.60.0.dist-info/entry_points.txt").decode()
    assert sorted(line.split(",")[0] for line in record) == sorted(names)
    assert not any(n.startswith(DROP["ray"]) for n in names)
    assert "ray = ray.scripts.scripts:main" in scripts and "rllib" not in scripts
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-index", "--no-deps", "--target", str(target),
                    str(done.path)], check=True, env={**os.environ, "PIP_CONSTRAINT": ""})
    assert (target / "ray" / "__init__.py").read_text() == "VERSION = '2.60.0'\n"
    assert os.access(target / "ray" / "core" / "bin" / "gcs_server", os.X_OK)
    assert not (target / "ray" / "jars").exists()
    binary = target / STRIP["ray"][1]
    assert binary.read_bytes()[:4] == b"\x7fELF" and len(binary.read_bytes()) <= len(ELF)
    assert subprocess.run([str(binary)], check=False).returncode == 0  # the stripped `true` still runs


def test_a_stale_folder_to_drop_is_refused(tmp_path: Path) -> None:
    src = fake_wheel(tmp_path, "ray", "2.60.0", {"ray/__init__.py": b""})
    with pytest.raises(ValueError, match="has no ray/jars/, ray/_raylet.so"):
        strip_wheel(src, tmp_path, ("ray/jars/",), ("ray/_raylet.so",))


def test_pins_follow_constraints_txt(tmp_path: Path) -> None:
    constraints = read_constraints(REPO / "constraints.txt")
    roots = root_requirements(constraints)
    assert f"ray[train]=={constraints['ray']}" in roots and f"webdataset=={constraints['webdataset']}" in roots
    assert f"mlflow-skinny=={constraints['mlflow']}" in roots  # released with mlflow, at its version
    check_pins([Pin("ray", constraints["ray"]), Pin("mlflow-skinny", constraints["mlflow"])], constraints)
    with pytest.raises(BundleError, match="mlflow-skinny resolved to 3.0.0 but constraints.txt pins mlflow=="):
        check_pins([Pin("mlflow-skinny", "3.0.0")], constraints)
    loose = tmp_path / "c.txt"
    loose.write_text("# pins\nray==2.60.0\nnumpy>=2\n")
    with pytest.raises(BundleError, match=r"c.txt:3: 'numpy>=2' is not an exact pin"):
        read_constraints(loose)


def test_the_bundle_leaves_out_the_image_and_the_unused() -> None:
    resolved = [Pin("ray", "2.60.0"), Pin("numpy", "2.4.6"), Pin("google-auth", "2.63.1"), Pin("webdataset", "1.0.2"),
                Pin("torch", "2.13.0"), Pin("cryptography", "50.0.2")]
    assert bundle_pins(resolved) == [Pin("cryptography", "50.0.2"), Pin("ray", "2.60.0"), Pin("webdataset", "1.0.2")]


def _wheels(tmp_path: Path) -> tuple[list[Pin], Path]:
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    fake_ray(wheels)
    fake_wheel(wheels, "webdataset", "1.0.2", {"webdataset/__init__.py": b"x = 1\n"})
    return [Pin("ray", "2.60.0"), Pin("webdataset", "1.0.2")], wheels


def test_a_bundle_installs_offline_with_its_script(tmp_path: Path) -> None:
    pins, wheels = _wheels(tmp_path)
    manifest = assemble(pins, wheels, tmp_path / "bundle", "3.12")
    assert json.loads((tmp_path / "bundle" / "bundle.json").read_text()) == manifest
    assert [w["file"] for w in manifest["wheels"]] == sorted(p.name for p in (tmp_path / "bundle").glob("*.whl"))
    assert [w["bytes"] for w in manifest["wheels"]] == [p.stat().st_size for p in
                                                         sorted((tmp_path / "bundle").glob("*.whl"))]
    subprocess.run(["sh", str(tmp_path / "bundle" / "install.sh"), str(tmp_path / "site")], check=True,
                   capture_output=True, env={**os.environ, "PIP_CONSTRAINT": "", "PYTHON": sys.executable})
    assert (tmp_path / "site" / "webdataset" / "__init__.py").exists() and not (tmp_path / "site/ray/jars").exists()


def test_an_overweight_bundle_is_refused_and_the_old_one_kept(tmp_path: Path) -> None:
    pins, wheels = _wheels(tmp_path)
    old = tmp_path / "bundle"
    old.mkdir()
    (old / "bundle.json").write_text("{}")
    with pytest.raises(BundleError, match=r"over its 0.001 MiB limit \(largest: ray-2.60.0"):
        assemble(pins, wheels, old, "3.12", limit_mib=0.001)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bundle", "wheels"]  # no half-built folder left
    assert (old / "bundle.json").read_text() == "{}"


def test_a_missing_wheel_names_the_package_and_the_fix(tmp_path: Path) -> None:
    pins, wheels = _wheels(tmp_path)
    with pytest.raises(BundleError, match=r"no wheel for alembic==1.20.1 in .*run `sray gpu-bundle` again"):
        assemble([*pins, Pin("alembic", "1.20.1")], wheels, tmp_path / "bundle", "3.12")
    with pytest.raises(BundleError, match=r"no wheel of alembic==1.20.1 for CPython 3.12 .* pin a version that has "
                                          r"one in constraints.txt"):
        download([Pin("alembic", "1.20.1")], tmp_path / "dl", "3.12", find_links=wheels)
    assert not (tmp_path / "bundle").exists()
