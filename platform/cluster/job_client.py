"""Ray Jobs API client side of ``sray submit``: submit a driver command, follow its log, map its end. The client
needs the cluster's token in its environment (``RAY_AUTH_MODE=token``, ``RAY_AUTH_TOKEN_PATH``/``RAY_AUTH_TOKEN``)."""

from __future__ import annotations

import asyncio
import sys
from typing import Any, TextIO

from ray.job_submission import JobSubmissionClient

EXIT_CODES = {"SUCCEEDED": 0, "FAILED": 1, "STOPPED": 3}
"""Exit status of ``sray submit --wait`` per final job status (the job statuses that do not change any more)."""


def submit(address: str, entrypoint: str, submission_id: str | None = None,
           runtime_env: dict[str, Any] | None = None) -> str:
    """Submit ``entrypoint`` (a shell command run on the head) to the dashboard at ``address``; the job id."""
    return JobSubmissionClient(address).submit_job(entrypoint=entrypoint, submission_id=submission_id,
                                                   runtime_env=runtime_env or None)


async def _follow(jobs: Any, job_id: str, out: TextIO, poll_s: float) -> str:
    """Stream the log while polling the status; at a final status, print what the stream has not shown yet
    from the whole log (the server closes the stream about 3 s after the job ends) and return the status."""
    written = 0

    async def tail() -> None:
        nonlocal written
        async for chunk in jobs.tail_job_logs(job_id):
            out.write(chunk)
            out.flush()
            written += len(chunk)

    streaming = asyncio.ensure_future(tail())
    try:
        while True:
            if streaming.done():
                await asyncio.sleep(poll_s)
            else:
                await asyncio.wait({streaming}, timeout=poll_s)
                if streaming.done() and streaming.exception() is not None:  # the head restarting: poll on
                    print(f"[sray] log stream of {job_id} ended ({type(streaming.exception()).__name__}); waiting "
                          "for the job's status", file=out, flush=True)
            status = str((await asyncio.to_thread(jobs.get_job_status, job_id)).value)
            if status in EXIT_CODES:
                break
    finally:
        streaming.cancel()
        await asyncio.gather(streaming, return_exceptions=True)
    try:
        rest = (await asyncio.to_thread(jobs.get_job_logs, job_id))[written:]
    except Exception:  # noqa: BLE001 - the status is known; a log that cannot be read is not an error of the job
        rest = ""
    out.write(rest)
    out.flush()
    return status


def follow(address: str, job_id: str, out: TextIO = sys.stdout, poll_s: float = 1.0) -> str:
    """Stream the job's log to ``out`` until it ends; return its final status (SUCCEEDED, FAILED, STOPPED)."""
    return asyncio.run(_follow(JobSubmissionClient(address), job_id, out, poll_s))
