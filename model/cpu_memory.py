"""Opt-in CPU allocator tuning for training loops (glibc only; changes process-wide state).

PyTorch's CPU tensors come from ``malloc``. glibc serves every request above its mmap threshold
(at most 32 MiB) with a fresh ``mmap`` and unmaps it on free, so each training step page-faults
all of its large temporaries in again: at the paper's configuration that is about 8 GB of minor
faults per 512 rays, a third of the step's CPU time spent in the kernel. Keeping freed memory in
the heap removes that cost once the first step has grown the heap. It is never done implicitly:
the training entry point (or a benchmark) calls ``keep_freed_memory`` once, early.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

_M_TRIM_THRESHOLD = -1  # glibc mallopt parameter numbers (malloc.h)
_M_MMAP_MAX = -4


def keep_freed_memory() -> bool:
    """Serve all allocations from the malloc heap and never trim it (glibc ``mallopt``).

    Returns True when applied, False where the C library is not glibc (nothing changes). The
    process keeps its peak heap size until it exits, so use it in long-running training or
    benchmark processes, not in short-lived tools that allocate a lot once.
    """
    if not sys.platform.startswith("linux"):
        return False
    path = ctypes.util.find_library("c")
    if path is None:
        return False
    libc = ctypes.CDLL(path)
    if not hasattr(libc, "mallopt") or not hasattr(libc, "gnu_get_libc_version"):
        return False
    ok_mmap = libc.mallopt(_M_MMAP_MAX, 0)
    ok_trim = libc.mallopt(_M_TRIM_THRESHOLD, 2**31 - 1)  # an int: the largest threshold it takes
    return bool(ok_mmap and ok_trim)
