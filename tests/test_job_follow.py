"""``sray submit --wait`` follows a job's log: it returns at the job's final status, even while the server keeps
the log stream open, prints every line of the log exactly once, and survives a broken stream. Checked against a
stand-in for Ray's ``JobSubmissionClient`` whose log and statuses the test scripts."""

from __future__ import annotations

import asyncio
import io
import time
from collections.abc import AsyncIterator

from sray.platform.cluster.job_client import _follow

LOG = "[sray] job x: checkpoints in /s/x\n[sray] step 10/10\n[sray] finished: best checkpoint /s/x/10\n"


class ScriptedJobs:
    """Streams the first ``streamed`` characters of ``LOG`` in two chunks, then either hangs (the server's
    late close) or raises (a head restart); the status turns final after ``running_polls`` polls."""

    def __init__(self, streamed: int, running_polls: int, final: str, breaks: bool) -> None:
        self.streamed, self.running_polls, self.final, self.breaks = streamed, running_polls, final, breaks
        self.polls = 0

    async def tail_job_logs(self, job_id: str) -> AsyncIterator[str]:
        half = self.streamed // 2
        for chunk in (LOG[:half], LOG[half:self.streamed]):
            yield chunk
            await asyncio.sleep(0.01)
        if self.breaks:
            raise RuntimeError("connection closed")
        await asyncio.sleep(60)

    def get_job_status(self, job_id: str) -> object:
        self.polls += 1
        status = "RUNNING" if self.polls <= self.running_polls else self.final

        class Status:
            value = status
        return Status()

    def get_job_logs(self, job_id: str) -> str:
        return LOG


def test_the_final_status_ends_the_wait_and_the_unstreamed_tail_is_printed_once() -> None:
    out = io.StringIO()
    jobs = ScriptedJobs(streamed=40, running_polls=2, final="SUCCEEDED", breaks=False)
    t0 = time.monotonic()
    assert asyncio.run(_follow(jobs, "raysubmit_1", out, poll_s=0.05)) == "SUCCEEDED"
    assert time.monotonic() - t0 < 10, "waited for the stream to close instead of the status"
    assert out.getvalue() == LOG


def test_a_broken_stream_falls_back_to_the_status_and_the_whole_log() -> None:
    out = io.StringIO()
    jobs = ScriptedJobs(streamed=20, running_polls=3, final="FAILED", breaks=True)
    assert asyncio.run(_follow(jobs, "raysubmit_2", out, poll_s=0.05)) == "FAILED"
    note = "[sray] log stream of raysubmit_2 ended (RuntimeError); waiting for the job's status\n"
    assert out.getvalue() == LOG[:20] + note + LOG[20:]
