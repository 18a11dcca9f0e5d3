"""CPU seconds a training rank has spent: its own process and every process it started (DataLoader workers).

``optim.cpu_seconds`` budgets a job by the CPU time summed over its ranks and their loader processes, a
quantity that does not depend on what else the machine is running (wall time on a shared 2-core machine
does). Each rank reads its own process tree here; the training step sums the ranks' readings in the
transfer it makes anyway (``TrainStep``).
"""

from __future__ import annotations

import psutil


def process_tree_cpu_seconds(process: psutil.Process | None = None) -> float:
    """User + system CPU seconds of ``process`` (default: this one), of its live descendants, and of the
    children that already exited and were waited for (a finished epoch's loader workers)."""
    process = process or psutil.Process()
    own = process.cpu_times()
    total = own.user + own.system + own.children_user + own.children_system
    for child in process.children(recursive=True):
        try:
            times = child.cpu_times()
        except (psutil.NoSuchProcess, psutil.AccessDenied):  # exited between the listing and the read
            continue
        total += times.user + times.system
    return total


class CpuClock:
    """A rank's CPU seconds since the job began, across resumes: the seconds recorded before this process
    started (``already_spent``) plus what this process tree has spent since the clock was made."""

    def __init__(self, already_spent: float = 0.0) -> None:
        """Start counting now, on top of ``already_spent`` seconds of this rank's earlier processes."""
        self.already_spent = already_spent
        self.start = process_tree_cpu_seconds()

    def seconds(self) -> float:
        """This rank's CPU seconds so far (earlier processes included)."""
        return self.already_spent + process_tree_cpu_seconds() - self.start
