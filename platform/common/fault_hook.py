"""The one fault-injection hook, ``SRAY_FAULTS="train.kill_at_step=12;fleet.fail_scenes=a,b"`` (:class:`Faults`)."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ENV_VAR = "SRAY_FAULTS"
KILL_MARKER = ".fault_kill_done"
"""File in a training job folder that records that the injected kill already happened."""
KILL_EXIT_CODE = 17
HOLD_TIMEOUT_S = 120.0
"""Longest pause at a ``train.hold_at_steps`` step when nobody releases it (then training goes on)."""


class InjectedFailure(RuntimeError):
    """Raised on purpose by ``fleet.fail_scenes`` (the failure a retry and a report must survive)."""


@dataclass(frozen=True)
class Faults:
    """The faults of this process's run (all off by default; -1 = never)."""

    kill_at_step: int = -1
    """Rank 0 exits abruptly (``os._exit``) at this step, on the first attempt only, so Ray Train restarts it."""
    nan_at_step: int = -1
    """The training loss at this step becomes NaN (the non-finite guard must skip it)."""
    stop_after_step: int = -1
    """Training stops cleanly with a checkpoint after this many steps, as after Ctrl-C."""
    hold_at_steps: tuple[int, ...] = ()
    """Rank 0 pauses before each listed step, once per job, so a drill can break something at a known step."""
    fail_scenes: tuple[str, ...] = ()
    """Every attempt of a fleet task for these scenes raises :class:`InjectedFailure`."""
    fail_trials: tuple[str, ...] = ()
    """Every launch of these sweep trials (keys such as ``t002``) raises :class:`InjectedFailure`."""
    nan_points: tuple[str, ...] = ()
    """Stability points (``method/axis/level``, level as the preset writes it) whose renders output NaN."""


_KEYS = {"train.kill_at_step": "kill_at_step", "train.nan_at_step": "nan_at_step",
         "train.stop_after_step": "stop_after_step", "train.hold_at_steps": "hold_at_steps",
         "fleet.fail_scenes": "fail_scenes", "sweep.fail_trials": "fail_trials", "stability.nan_points": "nan_points"}
_LISTS = ("fail_scenes", "fail_trials", "nan_points")
_INT_LISTS = ("hold_at_steps",)


def parse_faults(text: str) -> Faults:
    """Parse a ``SRAY_FAULTS`` value; an unknown key or a bad number is a ``ValueError`` naming it."""
    values: dict[str, object] = {}
    for entry in filter(None, (part.strip() for part in text.split(";"))):
        key, sep, raw = entry.partition("=")
        key = key.strip()
        if not sep or key not in _KEYS:
            raise ValueError(f"{ENV_VAR}: cannot read {entry!r}; write key=value entries separated by ';' "
                             f"with keys {sorted(_KEYS)}")
        field = _KEYS[key]
        items = tuple(s.strip() for s in raw.split(",") if s.strip())
        if field in _LISTS:
            values[field] = items
            continue
        try:
            values[field] = tuple(int(s) for s in items) if field in _INT_LISTS else int(raw)
        except ValueError:
            what = "comma-separated integer steps" if field in _INT_LISTS else "an integer step"
            raise ValueError(f"{ENV_VAR}: {key} must be {what}, got {raw!r}") from None
    return Faults(**values)  # type: ignore[arg-type]


def active_faults() -> Faults:
    """The faults set in this process's environment (none when ``SRAY_FAULTS`` is unset)."""
    return parse_faults(os.environ.get(ENV_VAR, ""))


def propagated_env() -> dict[str, str]:
    """``{"SRAY_FAULTS": value}`` when set here, else ``{}``: the ``env_vars`` of a Ray runtime env."""
    value = os.environ.get(ENV_VAR, "")
    return {ENV_VAR: value} if value else {}


def kill_if_due(faults: Faults, step: int, rank: int, job_dir: Path, before_exit: Callable[[], None]) -> None:
    """Exit this process abruptly at ``faults.kill_at_step`` (rank 0, first attempt only), after ``before_exit``."""
    marker = job_dir / KILL_MARKER
    if rank != 0 or step != faults.kill_at_step or marker.exists():
        return
    marker.touch()
    before_exit()
    os._exit(KILL_EXIT_CODE)


def hold_paths(job_dir: Path, step: int) -> tuple[Path, Path]:
    """``(marker, release)`` files of a ``train.hold_at_steps`` pause at ``step`` in ``job_dir``."""
    return job_dir / f".fault_hold_{step}.json", job_dir / f".fault_release_{step}"


def hold_if_due(faults: Faults, step: int, rank: int, job_dir: Path, facts: Callable[[], dict[str, Any]],
                timeout_s: float = HOLD_TIMEOUT_S, poll_s: float = 0.1) -> bool:
    """Pause rank 0 before a listed ``step`` once per job (marker: ``facts()``, pid, step); True when it paused."""
    marker, release = hold_paths(job_dir, step)
    if rank != 0 or step not in faults.hold_at_steps or marker.exists():
        return False
    partial = marker.with_suffix(".tmp")
    partial.write_text(json.dumps({**facts(), "pid": os.getpid(), "step": step}))
    partial.replace(marker)  # whole or absent: a reader never sees half a marker
    deadline = time.monotonic() + timeout_s
    while not release.exists() and time.monotonic() < deadline:
        time.sleep(poll_s)
    return True


def poisoned_point(method: str, axis: str, level: object) -> bool:
    """True when ``stability.nan_points`` lists this (method, axis, level) of the stability suite."""
    return f"{method}/{axis}/{level}" in active_faults().nan_points


def error_text(error: BaseException) -> str:
    """``Type: last message line`` of a failure, at most 2,000 characters: a fleet task's or sweep trial's record."""
    lines = str(error).strip().splitlines()
    return f"{type(error).__name__}: {lines[-1] if lines else ''}"[:2000]


def fail_if_listed(scene: str, attempt: int) -> None:
    """Raise :class:`InjectedFailure` when ``scene`` is listed in ``fleet.fail_scenes``."""
    if scene in active_faults().fail_scenes:
        raise InjectedFailure(f"scene {scene!r} is listed in {ENV_VAR} fleet.fail_scenes; attempt {attempt}")


def fail_trial_if_listed(key: str) -> None:
    """Raise :class:`InjectedFailure` when the sweep trial ``key`` is listed in ``sweep.fail_trials``."""
    if key in active_faults().fail_trials:
        raise InjectedFailure(f"sweep trial {key!r} is listed in {ENV_VAR} sweep.fail_trials")
