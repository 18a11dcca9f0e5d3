"""Bad training inputs fail before Ray starts: exit 2, one line naming the field and the fix, no
traceback, with Ray never even imported (when Ray Train found them it took a minute and 183 lines)."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from train_fixtures import tiny_shards  # noqa: E402,F401  (pytest fixture, used by name)

WITHOUT_RAY = "import sys; sys.modules['ray'] = None; from sray.jobs.cli import main; sys.exit(main(sys.argv[1:]))"
"""The CLI with ``ray`` made unimportable: any path that reaches Ray raises instead of refusing the input."""

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


@pytest.mark.parametrize(("flags", "message"), BAD, ids=[m[:24] for _, m in BAD])
def test_bad_train_input_fails_fast_with_one_line(flags: list[str], message: str, tiny_shards: Path,
                                                  tmp_path: Path) -> None:
    data = [] if "--data" in flags else ["--data", str(tiny_shards)]
    done = subprocess.run([sys.executable, "-c", WITHOUT_RAY, "train", *data, *flags,
                           "--set", f"run.output_dir={tmp_path / 'jobs'}"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in done.stderr + done.stdout, lines
    assert not (tmp_path / "jobs").exists() or not any((tmp_path / "jobs").iterdir())


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
