"""A local Ray started by sray gives its workers PyTorch's huge-page CPU allocator path."""

from __future__ import annotations

import os
import subprocess
import sys

_PROBE = """
import ray
from sray.platform.train.launcher import init_ray

@ray.remote(num_cpus=1)
def probe():
    import os, torch
    x = torch.empty(64 * 2**20 // 4)
    return os.environ.get("THP_MEM_ALLOC_ENABLE"), x.data_ptr() % 4096

init_ray(None, num_cpus=1)
env, offset = ray.get(probe.remote())
print(env, offset)
ray.shutdown()
"""


def _run_probe(extra_env: dict[str, str]) -> tuple[str, int]:
    env = {k: v for k, v in os.environ.items() if k != "THP_MEM_ALLOC_ENABLE"} | extra_env
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    value, offset = out.stdout.split()[-2:]
    return value, int(offset)


def test_local_workers_take_pytorchs_huge_page_path() -> None:
    value, offset = _run_probe({})
    assert value == "1"
    # PyTorch's THP path page-aligns blocks of 2 MiB or more (then madvises MADV_HUGEPAGE);
    # its default path asks for 64-byte alignment, which glibc's mmap'd chunks meet at offset 64.
    assert offset == 0


def test_a_users_own_setting_is_kept() -> None:
    value, offset = _run_probe({"THP_MEM_ALLOC_ENABLE": "0"})
    assert value == "0"
    assert offset != 0
