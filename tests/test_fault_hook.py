"""The fault hook: ``SRAY_FAULTS`` parsing, its errors, and each fault's effect in a real process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from injected_faults import injected_faults

from sray.platform.common.fault_hook import (
    ENV_VAR,
    KILL_EXIT_CODE,
    KILL_MARKER,
    Faults,
    InjectedFailure,
    active_faults,
    fail_if_listed,
    hold_if_due,
    hold_paths,
    parse_faults,
    propagated_env,
)


def test_parse_reads_every_key_and_defaults_to_off() -> None:
    assert parse_faults("") == Faults()
    got = parse_faults(" train.kill_at_step=12 ; train.nan_at_step=7;train.stop_after_step=10;fleet.fail_scenes=a, b ;"
                       "train.hold_at_steps=2, 7")
    assert got == Faults(kill_at_step=12, nan_at_step=7, stop_after_step=10, fail_scenes=("a", "b"),
                         hold_at_steps=(2, 7))


@pytest.mark.parametrize("text, named", [("train.kill_at=3", "train.kill_at"), ("train.nan_at_step=x", "integer"),
                                         ("fleet.fail_scenes", "key=value"),
                                         ("train.hold_at_steps=2,x", "comma-separated integer steps")])
def test_parse_errors_name_the_entry_and_the_fix(text: str, named: str) -> None:
    with pytest.raises(ValueError, match=ENV_VAR) as err:
        parse_faults(text)
    assert named in str(err.value)


def test_env_is_read_and_forwarded_only_while_set(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert active_faults() == Faults() and propagated_env() == {}
    with injected_faults("fleet.fail_scenes=s1"):
        assert active_faults().fail_scenes == ("s1",)
        assert propagated_env() == {ENV_VAR: "fleet.fail_scenes=s1"}
        with pytest.raises(InjectedFailure, match="'s1'"):
            fail_if_listed("s1", attempt=1)
        fail_if_listed("s2", attempt=1)
    assert active_faults() == Faults()


KILL_SCRIPT = """
import sys
from pathlib import Path
from sray.platform.common.fault_hook import active_faults, kill_if_due
job = Path(sys.argv[1])
for step in range(5):
    kill_if_due(active_faults(), step, int(sys.argv[2]), job, before_exit=lambda: print("flushed", flush=True))
    print("step", step, flush=True)
"""


def _run_kill_script(job: Path, rank: int, env_faults: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, **{ENV_VAR: env_faults})
    return subprocess.run([sys.executable, "-c", KILL_SCRIPT, str(job), str(rank)], env=env, capture_output=True,
                          text=True, timeout=120)


def test_kill_happens_once_on_rank_zero_only(tmp_path: Path) -> None:
    """A real process dies at the step (after the flush), leaves the marker; a restart runs through."""
    first = _run_kill_script(tmp_path, 0, "train.kill_at_step=3")
    assert first.returncode == KILL_EXIT_CODE and first.stdout.split("\n")[-2] == "flushed"
    assert "step 2" in first.stdout and "step 3" not in first.stdout
    assert (tmp_path / KILL_MARKER).exists()
    again = _run_kill_script(tmp_path, 0, "train.kill_at_step=3")
    assert again.returncode == 0 and "step 4" in again.stdout
    other = tmp_path / "rank1"
    other.mkdir()
    assert _run_kill_script(other, 1, "train.kill_at_step=3").returncode == 0


def test_hold_pauses_rank_zero_once_until_released(tmp_path: Path) -> None:
    """The marker appears while the pause lasts (with the given facts); the release ends it; the same step
    never pauses twice in one job folder, nor on another rank, nor at an unlisted step."""
    faults = parse_faults("train.hold_at_steps=3")
    marker, release = hold_paths(tmp_path, 3)
    paused: list[bool] = []
    waiter = threading.Thread(target=lambda: paused.append(hold_if_due(faults, 3, 0, tmp_path, lambda: {"node": "n"})))
    waiter.start()
    deadline = time.monotonic() + 30
    while not marker.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)
    assert waiter.is_alive() and json.loads(marker.read_text()) == {"node": "n", "pid": os.getpid(), "step": 3}
    release.touch()
    waiter.join(timeout=10)
    assert paused == [True]
    assert not hold_if_due(faults, 3, 0, tmp_path, dict, timeout_s=30)
    assert not hold_if_due(faults, 2, 0, tmp_path, dict, timeout_s=30)
    other = tmp_path / "other"
    other.mkdir()
    assert not hold_if_due(faults, 3, 1, other, dict, timeout_s=30) and not hold_paths(other, 3)[0].exists()
