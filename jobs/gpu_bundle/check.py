"""``sray gpu-bundle --check`` (minutes): install the bundle in a clean venv standing in for the GPU image (CPU torch,
the image's packages at our versions) and dry-run the prepared GPU call there: a missing wheel fails here."""

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
"""The package the stand-in takes from ``constraints.txt`` first (its CPU build)."""
RESULT = "check.json"
SCRIPT = "jobs/gpu_check/gpu_run.sh"
STAGES = "ray fleet minutes"
"""The stages that need the bundle."""
CPU_BUDGET_S = 3600
"""The script's time budget here (its default is sized for a GPU call)."""


def _run(step: str, command: list[str], env: dict[str, str] | None = None) -> None:
    """Run one step of the check, printing it; raises :class:`BundleError` with pip's or the stage's last lines."""
    print(f"[gpu-bundle check] {step}", flush=True)
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-15:])
        raise BundleError(f"{step} failed (exit {done.returncode}):\n{tail}")


def run_bundle_check(work: Path, python_version: str, constraints_file: Path, limit_mib: float) -> int:
    """Build, install and run the stages under ``work``; gpu-check's exit code (else :class:`BundleError`)."""
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
    run_dir = work / "gpu-run"
    shutil.rmtree(run_dir, ignore_errors=True)  # a check starts from nothing: no earlier world or report
    print(f"[gpu-bundle check] {SCRIPT} with DRY_RUN=1, stages {STAGES}", flush=True)
    run_env = {**os.environ, "OUT": str(run_dir / "out"), "WORK": str(run_dir / "work"), "BUNDLE": str(work / "bundle"),
               "RESUME": str(run_dir / "no-earlier-call"), "PYTHON": python, "DRY_RUN": "1", "STAGES": STAGES,
               "BUDGET_S": str(CPU_BUDGET_S)}
    for name in ("PIP_CONSTRAINT", "PYTHONPATH"):  # the venv sees the bundle and the checkout, nothing of this one
        run_env.pop(name, None)
    code = subprocess.run(["sh", str(checkout_root() / SCRIPT)], env=run_env, check=False).returncode
    stages = load_report(run_dir / "work" / "check")["stages"]
    result = {"python_version": python_version, "bundle_mib": round(folder_bytes(work / "bundle") / 2**20, 1),
              "wheels": len(manifest["wheels"]), "script_exit": code,
              "stages": {name: f"{r.status}: {r.summary}" for name, r in stages.items()},
              "seconds": round(time.perf_counter() - start), "report": "gpu-run/out/gpu_check.md"}
    atomic_write_json(work / RESULT, result)
    print(f"[gpu-bundle check] {'passed' if code == 0 else 'FAILED'}: {result}", flush=True)
    return code
