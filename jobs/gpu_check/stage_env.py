"""Stages ``environment`` (what the machine is) and ``tests`` (the suite's GPU and model tests, run here)."""

from __future__ import annotations

import subprocess
import sys
import time
from importlib.metadata import PackageNotFoundError, version

import torch

from .context import CheckContext, has_module
from .report import StageResult

GPU_TEST_FILES = ("tests/test_model_gpu.py", "tests/test_model_rendering.py")
"""Files holding the tests marked ``gpu``."""
MODEL_TEST_FILES = ("tests/test_model_sray.py", "tests/test_model_attention.py", "tests/test_model_weights.py",
                    "tests/test_weight_cross_view.py", "tests/test_model_precision.py", "tests/test_train_step.py")
"""Model-level tests that need torch alone (no Ray, MLflow or webdataset)."""
DRY_RUN_TESTS = ("tests/test_model_gpu.py",
                 "tests/test_model_weights.py::test_radial_weights_come_within_one_percent_of_both_bounds")
"""A dry run only proves the stage runs."""


def environment(ctx: CheckContext) -> StageResult:
    """GPU name and memory, driver/CUDA/cuDNN versions, torch build, NCCL, and the optional packages."""
    rows = [["torch", torch.__version__], ["CUDA (torch build)", str(torch.version.cuda)],
            ["device", str(ctx.device)]]
    if ctx.device.type == "cuda":
        props = torch.cuda.get_device_properties(ctx.device)
        rows += [["GPU", props.name], ["GPU memory GiB", f"{props.total_memory / 2**30:.1f}"],
                 ["compute capability", f"{props.major}.{props.minor}"],
                 ["cuDNN", str(torch.backends.cudnn.version())],
                 ["driver", _nvidia_smi_driver()]]
    rows.append(["NCCL", str(torch.distributed.is_nccl_available()) if torch.distributed.is_available() else "no"])
    rows += [[name, _version(name)] for name in ("accelerate", "ray", "mlflow", "webdataset", "pytest")]
    gpu = next((r[1] for r in rows if r[0] == "GPU"), "no GPU (dry run)")
    return StageResult("passed", f"{gpu}, torch {torch.__version__}", header=["what", "value"], rows=rows)


def _version(name: str) -> str:
    if not has_module(name):
        return "not installed"
    try:
        return version(name)
    except PackageNotFoundError:
        return "installed (no metadata)"


def _nvidia_smi_driver() -> str:
    try:
        done = subprocess.run(["nvidia-smi", "--query-gpu=driver_version", "--format=csv,noheader"],
                              capture_output=True, text=True, timeout=30, check=False)
        return done.stdout.strip() or "unknown"
    except (OSError, subprocess.TimeoutExpired):
        return "unknown (no nvidia-smi)"


def tests(ctx: CheckContext) -> StageResult:
    """The suite's GPU-marked tests and the torch-only model tests, with pytest, on this machine."""
    if not has_module("pytest"):
        return StageResult("skipped", "pytest is not installed here")
    runs = [("dry run", list(DRY_RUN_TESTS))] if ctx.dry_run else [
        ("marked gpu", ["-m", "gpu", *GPU_TEST_FILES]), ("model tests", list(MODEL_TEST_FILES))]
    rows, failed = [], False
    for label, args in runs:
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
                              cwd=ctx.repo, capture_output=True, text=True, check=False)
        tail = (done.stdout.strip().splitlines() or ["(no output)"])[-1]
        (ctx.out / f"tests-{label.replace(' ', '-')}.log").write_text(done.stdout + done.stderr)
        failed |= done.returncode not in (0, 5)  # 5: nothing collected (e.g. every test deselected)
        rows.append([label, tail, f"{time.perf_counter() - start:.0f}"])
    return StageResult("failed" if failed else "passed", "; ".join(f"{r[0]}: {r[1]}" for r in rows),
                       header=["tests", "pytest summary", "seconds"], rows=rows)
