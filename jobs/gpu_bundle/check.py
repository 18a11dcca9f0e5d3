"""``sray gpu-bundle --check``: the bundle, built for this machine's Python, installed offline into a clean venv
that stands in for the GPU image (the CPU torch, and the image's packages at this environment's versions), then
gpu-check's ``ray`` and ``fleet`` stages run there on the CPU. A wheel missing from the bundle fails here, not on
the GPU. Slow (a few minutes: a venv, two installs and the stages); the suite tests the builder's parts instead.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from sray.data_tools.atomic import atomic_write_json
from sray.jobs.gpu_check.context import checkout_root
from sray.jobs.gpu_check.report import load_report

from .build import build_bundle, folder_bytes
from .image import IMAGE_PACKAGES, IMAGE_SIDE_NEEDS
from .resolve import BundleError, environment_constraints, read_constraints, resolve

TORCH_PIN = "torch"
"""The one package the stand-in takes from ``constraints.txt`` first (its CPU build, as this machine has)."""
RESULT = "check.json"
"""What the check found: bundle size, the stages' status, seconds."""


def sray_path_dir(folder: Path, repo: Path) -> Path:
    """A folder holding ``sray/<part>`` links to the checkout's four top-level folders: on ``PYTHONPATH`` it makes
    ``sray`` importable without pip (how the GPU image runs sray, docs/gpu.md); returns ``folder``."""
    package = folder / "sray"
    shutil.rmtree(folder, ignore_errors=True)
    package.mkdir(parents=True)
    for part in ("model", "data_tools", "platform", "jobs"):
        (package / part).symlink_to(repo / part, target_is_directory=True)
    return folder


def _run(step: str, command: list[str], env: dict[str, str] | None = None) -> None:
    """Run one step of the check, printing it; raises :class:`BundleError` with pip's or the stage's last lines."""
    print(f"[gpu-bundle check] {step}", flush=True)
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-15:])
        raise BundleError(f"{step} failed (exit {done.returncode}):\n{tail}")


def run_bundle_check(work: Path, python_version: str, constraints_file: Path, limit_mib: float) -> int:
    """Build, install and run the stages under ``work``; returns gpu-check's exit code (0: both stages passed).

    Raises :class:`BundleError` when the bundle cannot be built or installed."""
    here = f"{sys.version_info.major}.{sys.version_info.minor}"
    if python_version != here:
        raise BundleError(f"--check installs into a venv of this Python ({here}), not {python_version}: drop "
                          "--python-version or pass this one")
    start, work = time.perf_counter(), work.resolve()
    constraints = read_constraints(constraints_file)
    manifest = build_bundle(work / "bundle", python_version, constraints_file, limit_mib)
    resolved = resolve(python_version, constraints_file)
    image_side = sorted({p.spec() for p in resolved if p.name in IMAGE_PACKAGES} | set(IMAGE_SIDE_NEEDS))
    frozen = environment_constraints(work / "environment.txt", constraints)
    venv = work / "venv"
    shutil.rmtree(venv, ignore_errors=True)
    python = str(venv / "bin" / "python")
    env = {**os.environ, "PIP_CONSTRAINT": str(constraints_file.resolve())}
    _run("a clean venv", [sys.executable, "-m", "venv", str(venv)])
    _run(f"the CPU torch ({TORCH_PIN}=={constraints[TORCH_PIN]})",
         [python, "-m", "pip", "install", "-q", f"{TORCH_PIN}=={constraints[TORCH_PIN]}"], env)
    _run(f"the image's {len(image_side)} other packages", [python, "-m", "pip", "install", "-q", "-c", str(frozen),
                                                             *image_side], env)
    site = work / "site"
    shutil.rmtree(site, ignore_errors=True)
    _run("the bundle, offline", ["sh", str(work / "bundle" / "install.sh"), str(site)], {**env, "PYTHON": python})
    path = sray_path_dir(work / "sray-path", checkout_root())
    stage_env = {**os.environ, "PYTHONPATH": f"{site}:{path}", "RAY_USAGE_STATS_ENABLED": "0"}
    stage_env.pop("PIP_CONSTRAINT", None)
    shutil.rmtree(work / "gpu-check", ignore_errors=True)  # a check starts from nothing: no earlier world or report
    print("[gpu-bundle check] gpu-check --dry-run --stages ray fleet", flush=True)
    code = subprocess.run([python, "-m", "sray.jobs.cli", "gpu-check", "--dry-run", "--stages", "ray",
                           "fleet", "--out", str(work / "gpu-check")], env=stage_env, check=False).returncode
    stages = load_report(work / "gpu-check")["stages"]
    result = {"python_version": python_version, "bundle_mib": round(folder_bytes(work / "bundle") / 2**20, 1),
              "wheels": len(manifest["wheels"]), "gpu_check_exit": code,
              "stages": {name: f"{r.status}: {r.summary}" for name, r in stages.items()},
              "seconds": round(time.perf_counter() - start), "report": "gpu-check/gpu_check.md"}
    atomic_write_json(work / RESULT, result)
    print(f"[gpu-bundle check] {'passed' if code == 0 else 'FAILED'}: {result}", flush=True)
    return code
