"""Bad training inputs fail before Ray starts: exit 2, one line naming the field and the fix, no
traceback, with Ray never even imported (when Ray Train found them it took a minute and 183 lines)."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from train_fixtures import tiny_shards  # noqa: E402,F401  (pytest fixture, used by name)

WITHOUT_RAY = """
import contextlib, io, json, sys
sys.modules["ray"] = None  # any path that reaches Ray raises instead of refusing the input
from sray.jobs.cli import main
results = []
for argv in json.loads(sys.argv[1]):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as stop:  # argparse's own refusals
            code = stop.code
    results.append({"code": code, "stdout": out.getvalue(), "stderr": err.getvalue()})
print(json.dumps(results))
"""
"""Runs the CLI once per argument list given as JSON, in one process with ``ray`` made unimportable, and prints
each run's exit code and output as JSON (one interpreter start for every case instead of one per case)."""

BAD = [
    (["--data", "/no/such/folder"], "/no/such/folder: no such shard folder"),
    (["--set", "optim.steps=many"], "'many' is not a valid int"),
    (["--set", "optim.nosuch=1"], "optim.nosuch"),
    (["--workers", "0"], "run.workers: must be at least 1"),
    (["--precision", "fp16"], "fp16 needs CUDA"),
    (["--workers", "2", "--gpus-per-worker", "0.5"], "refuses two ranks on one GPU"),
    (["--tracker", "nosuch"], "unknown tracker 'nosuch'"),
    (["--tracking-uri", "http://127.0.0.1:9"], "does not answer"),
    (["--resume", "never-ran"], "no job called 'never-ran'"),
    (["--address", "127.0.0.1:9"], "--address 127.0.0.1:9: no Ray cluster answers there"),
    (["--address", "head-without-port"], "expected HOST:PORT of the Ray head"),
]


@pytest.fixture(scope="module")
def refusals(tiny_shards: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict]]:  # noqa: F811
    """(folder, one result per case of ``BAD``): every case run by ``sray train`` without Ray, each with its own
    output folder ``folder/case<i>``."""
    folder = tmp_path_factory.mktemp("refusals")
    cases = [["train", *([] if "--data" in flags else ["--data", str(tiny_shards)]), *flags,
              "--set", f"run.output_dir={folder / f'case{i}'}"] for i, (flags, _) in enumerate(BAD)]
    done = subprocess.run([sys.executable, "-c", WITHOUT_RAY, json.dumps(cases)], capture_output=True, text=True,
                          timeout=300, cwd=folder)
    assert done.returncode == 0, done.stderr[-3000:]
    return folder, json.loads(done.stdout.splitlines()[-1])


@pytest.mark.parametrize("case", range(len(BAD)), ids=[m[:24] for _, m in BAD])
def test_bad_train_input_fails_fast_with_one_line(case: int, refusals: tuple[Path, list[dict]]) -> None:
    folder, results = refusals
    result, message = results[case], BAD[case][1]
    lines = [line for line in result["stderr"].splitlines() if line.strip()]
    assert result["code"] == 2, result
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in result["stderr"] + result["stdout"], lines
    jobs = folder / f"case{case}"
    assert not jobs.exists() or not any(jobs.iterdir())


def test_submit_refuses_bad_input_before_contacting_the_cluster(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "sray.jobs.cli", "submit", "--address", "http://127.0.0.1:9",
                           "--data", "/no/such/folder"], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.startswith("sray submit: /no/such/folder: no such shard folder")


def test_ray_train_controller_query_warnings_are_dropped_and_others_kept() -> None:
    from sray.platform.common.ray_env import QUIET, quiet_ray_logs

    name = next(iter(QUIET))
    logger = logging.getLogger(name)
    quiet_ray_logs()
    quiet_ray_logs()
    seen: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: seen.append(record.getMessage())  # type: ignore[method-assign]
    logger.addHandler(handler)
    try:
        logger.warning("Failed to query Ray Train Controller actor state. State API may be temporarily unavailable.")
        logger.warning("Detected that the Ray Train controller actor (x) is dead.")
    finally:
        logger.removeHandler(handler)
    assert seen == ["Detected that the Ray Train controller actor (x) is dead."]
    assert len(logger.filters) == 1
