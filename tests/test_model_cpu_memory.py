"""keep_freed_memory stops large tensors from being page-faulted in again on every allocation."""

from __future__ import annotations

import subprocess
import sys

import pytest

_PROBE = """
import resource, sys, torch
from sray.model.cpu_memory import keep_freed_memory
applied = keep_freed_memory() if sys.argv[1] == "heap" else None
for i in range(3):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    x = torch.ones(64 * 2**20 // 4)  # 64 MiB, above glibc's largest mmap threshold
    del x
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
print(applied, faults)
"""


def _last_faults(mode: str) -> tuple[str, int]:
    out = subprocess.run([sys.executable, "-c", _PROBE, mode], capture_output=True, text=True, check=True)
    applied, faults = out.stdout.split()
    return applied, int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc mallopt is Linux-only")
def test_heap_mode_reuses_freed_memory_without_page_faults() -> None:
    applied, faults_heap = _last_faults("heap")
    _, faults_default = _last_faults("default")
    assert applied == "True"
    assert faults_default > 10_000  # 64 MiB in 4 KiB pages is 16384 faults when unmapped each time
    assert faults_heap < 1_000
