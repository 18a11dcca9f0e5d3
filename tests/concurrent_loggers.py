"""N processes logging into N MLflow runs at once through sray's real logger (a script the cluster tests run).

    python tests/concurrent_loggers.py TRACKING_URI EXPERIMENT RUNS STEPS

Prepares a parent run and RUNS child runs (as a fleet does), then starts RUNS processes that wait at one
barrier and each log STEPS steps of :data:`KEYS` (value of key k at step s: ``s * (k + 1)``) through
:class:`sray.platform.tracking.logger.MlflowRunLogger`, flushing every 5 steps, and close their run.
Prints one JSON line: the parent run id, the child run ids and each process's exit code. The processes
come from a fork server that imported mlflow once (16 fresh interpreters would cost 16 imports of it).
"""

from __future__ import annotations

import json
import multiprocessing
import sys

KEYS = ("storm/a", "storm/b", "storm/c", "storm/d")
"""Metrics every process logs at every step."""


def log_run(handle: object, steps: int, barrier: object) -> None:
    """One process: wait for all, log ``steps`` steps of :data:`KEYS` into ``handle``'s run, close it."""
    from sray.platform.tracking.logger import MlflowRunLogger

    logger = MlflowRunLogger(handle, flush_every_steps=5, retry_initial_s=0.5, retry_max_s=2.0, close_timeout_s=90,
                             close_poll_s=0.5)
    barrier.wait(timeout=120)
    for step in range(steps):
        logger.log_metrics({key: step * (k + 1) for k, key in enumerate(KEYS)}, step)
    logger.close("FINISHED")
    if logger.pending() != {"params": 0, "metrics": 0, "ops": 0}:
        sys.exit(3)


def main(uri: str, experiment: str, runs: int, steps: int) -> dict[str, object]:
    """Prepare the runs, log into them from ``runs`` processes at once; what was made and how they ended."""
    from sray.platform.tracking.mlflow_tracker import MlflowTracker

    tracker = MlflowTracker(uri)
    parent = tracker.start_run(experiment, "storm-parent")
    children = [tracker.start_run(experiment, f"storm-{i:02d}", parent=parent) for i in range(runs)]
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["mlflow", "sray.platform.tracking.logger"])
    barrier = context.Barrier(runs)
    procs = [context.Process(target=log_run, args=(child, steps, barrier)) for child in children]
    for proc in procs:
        proc.start()
    for proc in procs:
        proc.join(timeout=150)
        if proc.exitcode is None:
            proc.kill()
            proc.join()
    tracker.end_run(parent, "FINISHED")
    return {"parent": parent.run_id, "runs": [c.run_id for c in children], "exit": [p.exitcode for p in procs]}


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))), flush=True)
