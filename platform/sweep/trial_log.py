"""The driver's record of every trial's results: history files, progress lines, the wall-time budget.

A Tune callback in the driver process (the only writer of ``history.jsonl`` and, for the budget, of stop
requests; ``trial_files``). A trial's running time is Tune's ``time_total_s`` of its current launch plus the
time its earlier launches had reached (from the history), so a resumed trial's curve and budget continue
where they were instead of starting at zero again.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from ray.tune import Callback
from ray.tune.result import AUTO_RESULT_KEYS, DEBUG_METRICS

from sray.platform.sweep.study import StudySettings
from sray.platform.sweep.trial_files import (BY_BUDGET, append_history, read_history, read_record,
                                             read_stop_request, request_stop, trial_folder)


_SKIPPED = frozenset(AUTO_RESULT_KEYS) | frozenset(DEBUG_METRICS)
"""Tune's own bookkeeping keys, left out of the history."""


def _point_text(point: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in point.items())


class TrialLog(Callback):
    """Records results with the trial's running time, prints a line per result, enforces the wall-time budget."""

    def __init__(self, settings: StudySettings, plan: Mapping[str, Mapping[str, Any]]) -> None:
        """``plan``: the study's points, printed when their trials start."""
        self.study = str(settings.folder)
        self.metric = settings.metric
        self.time_attr = settings.time_attr
        self.wall_budget_s = settings.wall_budget_s
        self.label = settings.label
        self.start_by = settings.start_by
        self.plan = {k: dict(v) for k, v in plan.items()}
        self._offsets: dict[tuple[str, int], float] = {}

    def __getstate__(self) -> dict[str, Any]:
        """Tune saves its callbacks with the experiment; a restored one measures offsets afresh."""
        return {k: v for k, v in self.__dict__.items() if k != "_offsets"} | {"_offsets": {}}

    def on_trial_start(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        """Print which point a trial runs."""
        key = trial.config["key"]
        if self.start_by and time.time() >= self.start_by:
            print(f"[{self.label}] {key} not started: no trial starts after the study's time limit", flush=True)
            return
        print(f"[{self.label}] {key} started: {_point_text(self.plan.get(key, {}))}", flush=True)

    def on_trial_result(self, iteration: int, trials: list[Any], trial: Any, result: dict[str, Any],
                        **info: Any) -> None:
        """Append the result to the trial's history; ask the trial to stop once past the wall-time budget."""
        key = trial.config["key"]
        folder = trial_folder(self.study, key)
        launch = max(len(read_record(folder).launches) - 1, 0)
        if (key, launch) not in self._offsets:
            earlier = [e["time_s"] for e in read_history(folder) if e.get("launch", 0) < launch]
            self._offsets[(key, launch)] = max(earlier, default=0.0)
        time_s = self._offsets[(key, launch)] + float(result.get("time_total_s", 0.0))
        values = {k: v for k, v in result.items()
                  if k not in _SKIPPED and isinstance(v, (int, float)) and not isinstance(v, bool)}
        append_history(folder, {"launch": launch, "time_s": round(time_s, 3)} | values)
        if self.metric in values:
            print(f"[{self.label}] {key} {self.time_attr} {values.get(self.time_attr)}: {self.metric} "
                  f"{values[self.metric]:.4g} ({time_s:.0f} s)", flush=True)
        if 0 < self.wall_budget_s <= time_s and read_stop_request(folder) is None:
            request_stop(folder, BY_BUDGET, values.get(self.time_attr))
            print(f"[{self.label}] {key} reached its wall-time budget ({self.wall_budget_s:.0f} s): stopping it",
                  flush=True)

    def on_trial_error(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        """Say that a trial failed (its error is in its record and in the results table)."""
        print(f"[{self.label}] {trial.config['key']} errored; the other trials go on", flush=True)
