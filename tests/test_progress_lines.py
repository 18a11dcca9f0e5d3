"""Progress as plain lines where a redrawn bar would leave a copy per redraw (files, job logs)."""

from __future__ import annotations

import pytest

from sray.platform.common import progress
from sray.platform.common.progress import PROGRESS_ENV, LineProgress, make_progress, progress_env, progress_mode


class FakeClock:
    """``time.monotonic`` under the test's control."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_lines_every_interval_with_rate_and_eta(monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    clock = FakeClock()
    monkeypatch.setattr(progress.time, "monotonic", clock)
    bar = LineProgress(total=100, initial=20, desc="job", every_s=30.0)
    for _ in range(10):  # 10 steps of 2 s: 20 s, under the interval, no line yet
        clock.now += 2.0
        bar.update()
    assert capsys.readouterr().out == ""
    bar.set_postfix(loss="0.500")
    for _ in range(5):  # 30 s since the start: one line; 15 steps in 30 s = 2 s/step, 65 steps left
        clock.now += 2.0
        bar.update()
    assert capsys.readouterr().out == "[sray] job: step 35/100 (35%), 2.00 s/step, ETA 2:10, loss=0.500\n"
    clock.now += 1.0
    bar.update(65)  # the last step always prints
    assert capsys.readouterr().out.startswith("[sray] job: step 100/100 (100%), ")
    bar.close()  # already shown: nothing more
    assert capsys.readouterr().out == ""


def test_close_prints_a_position_not_shown_yet(capsys) -> None:
    bar = LineProgress(total=10, desc="x", every_s=1e9)
    bar.update(3)
    bar.close()
    assert capsys.readouterr().out.startswith("[sray] x: step 3/10 (30%), ")


def test_mode_follows_the_env_else_the_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(PROGRESS_ENV, "bar")
    assert progress_mode() == "bar" and progress_env() == {PROGRESS_ENV: "bar"}
    monkeypatch.delenv(PROGRESS_ENV)
    monkeypatch.setattr(progress.sys.stdout, "isatty", lambda: False, raising=False)
    assert progress_mode() == "lines"
    assert isinstance(make_progress(True, total=5), LineProgress)
    assert not isinstance(make_progress(False, total=5), LineProgress)
