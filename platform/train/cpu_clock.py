"""CPU seconds a training rank has spent, its loader workers included (``optim.cpu_seconds`` budgets their sum)."""

from __future__ import annotations

import psutil


def process_tree_cpu_seconds(process: psutil.Process | None = None) -> float:
    """User + system CPU seconds of ``process`` (default: this one), its descendants and its exited children."""
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
    """A rank's CPU seconds since the job began: ``already_spent`` by earlier processes, plus this tree's."""

    def __init__(self, already_spent: float = 0.0) -> None:
        self.already_spent, self.start = already_spent, process_tree_cpu_seconds()

    def seconds(self) -> float:
        """This rank's CPU seconds so far (earlier processes included)."""
        return self.already_spent + process_tree_cpu_seconds() - self.start
