"""What ``sray train`` prints when its output goes to a file or a job log: each worker line once,
progress as plain lines (no carriage-return redraws), none of Ray Train's per-checkpoint internals, and no
traceback from Ray's own actors while another Ray runs on the machine (the test session's)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from train_fixtures import tiny_shards  # noqa: F401

from sray.platform.common.progress import PROGRESS_ENV

TINY = ("model.n_source=3", "model.n_coarse=8", "model.n_fine=8", "data.top_k=4", "data.rays_per_batch=64",
        "data.loader_workers=0", "optim.steps=6", "run.val_every=100", "run.ckpt_every=6", "run.register_model=")


def test_a_job_writing_to_a_file_prints_each_worker_line_once(ray_session, tiny_shards: Path,  # noqa: F811  (conftest)
                                                             tmp_path: Path) -> None:
    sets = [a for s in (*TINY, f"run.output_dir={tmp_path / 'jobs'}") for a in ("--set", s)]
    cmd = [sys.executable, "-m", "sray.jobs.cli", "train", "--recipe", "synth-small", "--data", str(tiny_shards),
           "--name", "printing", "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}", *sets]
    env = {k: v for k, v in __import__("os").environ.items() if k not in (PROGRESS_ENV, "RAY_ADDRESS")}
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    text = done.stdout + done.stderr  # a user's terminal (or job log) shows both streams
    worker_lines = [ln for ln in text.splitlines() if "RayTrainWorker pid=" in ln and "[sray]" in ln]
    assert sum("[sray] finished 6 steps" in ln for ln in worker_lines) == 1, worker_lines  # Ray Train's print
    assert len(worker_lines) == len(set(worker_lines)), worker_lines                      # patch sent each twice
    assert any("[sray] printing: step 6/6 (100%)" in ln for ln in worker_lines), worker_lines
    assert "\r" not in text
    # Ray Train's placement-group cleaner looked its cluster up with address="auto" and, with the session's
    # Ray beside this job's, died with "Found multiple active Ray instances"
    assert "Traceback" not in text and "multiple active Ray instances" not in text, text[-3000:]
    # Ray Train's own lines at each checkpoint (ray_env.QUIET): each worker's report, rank 0's storage copy
    assert "Reporting training result" not in text and "Checkpoint successfully created" not in text, text[-3000:]
