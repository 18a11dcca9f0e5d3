"""Ray Jobs API client side of ``sray submit``: submit a driver command, follow its log, map its end.

The client needs the cluster's token in its environment (``RAY_AUTH_MODE=token`` and
``RAY_AUTH_TOKEN_PATH``/``RAY_AUTH_TOKEN``); Ray's client adds it to every request.
"""

from __future__ import annotations

import asyncio
import sys
import time
from typing import Any, TextIO

EXIT_CODES = {"SUCCEEDED": 0, "FAILED": 1, "STOPPED": 3}
"""Exit status of ``sray submit --wait`` per final job status (anything else: 1)."""


def client(address: str) -> Any:
    """A ``JobSubmissionClient`` for the dashboard at ``address`` (http://host:port)."""
    from ray.job_submission import JobSubmissionClient

    return JobSubmissionClient(address)


def submit(address: str, entrypoint: str, submission_id: str | None = None,
           runtime_env: dict[str, Any] | None = None) -> str:
    """Submit ``entrypoint`` (a shell command run on the head) and return the job id."""
    return client(address).submit_job(entrypoint=entrypoint, submission_id=submission_id,
                                      runtime_env=runtime_env or None)


async def _tail(jobs: Any, job_id: str, out: TextIO) -> None:
    async for chunk in jobs.tail_job_logs(job_id):
        out.write(chunk)
        out.flush()


def follow(address: str, job_id: str, out: TextIO = sys.stdout, poll_s: float = 1.0) -> str:
    """Stream the job's log to ``out`` until it ends; return its final status (SUCCEEDED, FAILED, STOPPED)."""
    jobs = client(address)
    try:
        asyncio.run(_tail(jobs, job_id, out))
    except Exception as e:  # noqa: BLE001 - the log stream broke (head restarting): fall back to polling
        print(f"[sray] log stream of {job_id} ended ({type(e).__name__}); waiting for the job's status", flush=True)
    while True:
        status = str(jobs.get_job_status(job_id).value)
        if status in ("SUCCEEDED", "FAILED", "STOPPED"):
            return status
        time.sleep(poll_s)


def job_info(address: str, job_id: str) -> Any:
    """The Jobs API's ``JobDetails`` of ``job_id`` (status, message, driver info)."""
    return client(address).get_job_info(job_id)
