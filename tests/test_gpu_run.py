"""``jobs/gpu_check/gpu_run.sh``, the prepared GPU call, on the CPU: it installs a bundle offline from a bare start,
runs the stages not yet in the report, returns 5 files, and a second call on a fresh machine given the first
call's files skips what is done and stops, saying so, before a stage its time budget cannot hold."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tarfile
from pathlib import Path

from test_gpu_bundle import fake_wheel

from sray.jobs.gpu_bundle.build import Pin, assemble

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "jobs" / "gpu_check" / "gpu_run.sh"


def call(tmp_path: Path, name: str, bundle: Path, resume: Path, **env: str) -> tuple[int, Path, str]:
    """One call of the script as on a fresh device: its own OUT and scratch folder; (exit code, OUT, log)."""
    out = tmp_path / name / "out"
    done = subprocess.run(["sh", str(SCRIPT)], capture_output=True, text=True, check=False, cwd=REPO, env={
        **os.environ, "OUT": str(out), "WORK": str(tmp_path / name / "work"), "BUNDLE": str(bundle),
        "RESUME": str(resume), "PYTHON": sys.executable, "DRY_RUN": "1", "PIP_CONSTRAINT": "", **env})
    return done.returncode, out, (out / "gpu-run.log").read_text() if (out / "gpu-run.log").exists() else done.stderr


def test_a_call_installs_the_bundle_and_a_second_resumes_within_its_budget(tmp_path: Path) -> None:
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    fake_wheel(wheels, "bundleprobe", "1.0", {"bundleprobe/__init__.py": b"MARK = 'from the bundle'\n"})
    bundle = tmp_path / "bundle"
    assemble([Pin("bundleprobe", "1.0")], wheels, bundle, "3.12")

    code, first, log = call(tmp_path, "first", bundle, tmp_path / "nothing", STAGES="environment")
    assert code == 0, log
    assert sorted(p.name for p in first.iterdir()) == ["docs.tar", "gpu-run.log", "gpu-run.tar", "gpu_check.json",
                                                       "gpu_check.md"]
    assert (tmp_path / "first" / "work" / "site" / "bundleprobe" / "__init__.py").exists()  # installed offline
    report = json.loads((first / "gpu_check.json").read_text())
    assert report["stages"]["environment"]["status"] == "passed"
    with tarfile.open(first / "gpu-run.tar") as tar:
        assert "./gpu_check.json" in tar.getnames()
    assert "environment: passed" in log

    # a fresh machine, the first call's report carried as RESUME, a budget too short for another stage
    carried = tmp_path / "carried"
    carried.mkdir()
    (carried / "gpu_check.json").write_bytes((first / "gpu_check.json").read_bytes())
    code, second, log = call(tmp_path, "second", bundle, carried, STAGES="environment precision", BUDGET_S="0",
                             DRY_RUN="0")
    assert code == 0, log
    assert "resuming: environment already done" in log and "environment: already in the report" in log
    assert re.search(r"precision needs about 120 s and -?\d+ s are left: stopping here", log), log
    assert json.loads((second / "gpu_check.json").read_text()) == report  # nothing lost, nothing run again


def test_without_a_bundle_it_stops_at_once_naming_the_fix(tmp_path: Path) -> None:
    code, out, log = call(tmp_path, "bare", tmp_path / "no-bundle", tmp_path / "nothing")
    assert code == 2 and "run make gpu-bundle" in log
    assert [p.name for p in out.iterdir()] == ["gpu-run.log"]
