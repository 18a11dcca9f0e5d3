"""A local Ray started by sray gives Ray Train's controller the 0.5 s poll (``sray.platform.common.ray_env``)
and leaves PyTorch's CPU allocator as the user set it (no huge-page path unless asked for: it was slower
in ``sray bench model``)."""

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
from ray.train.v2._internal.constants import get_env_vars_to_propagate
print(get_env_vars_to_propagate().get("RAY_TRAIN_HEALTH_CHECK_INTERVAL_S"), env, offset)
ray.shutdown()
"""


def _run_probe(extra_env: dict[str, str]) -> tuple[str, str, int]:
    """(poll interval Ray Train passes to its controller, THP_MEM_ALLOC_ENABLE in a worker, a block's page offset)."""
    ours = ("THP_MEM_ALLOC_ENABLE", "RAY_TRAIN_HEALTH_CHECK_INTERVAL_S")
    env = {k: v for k, v in os.environ.items() if k not in ours} | extra_env
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    poll, value, offset = out.stdout.split()[-3:]
    return poll, value, int(offset)


def test_local_workers_poll_fast_and_keep_the_default_allocator() -> None:
    poll, value, offset = _run_probe({})
    assert value == "None" and poll == "0.5"
    # PyTorch's default path asks for 64-byte alignment, which glibc's mmap'd chunks meet at offset 64;
    # its THP path would page-align blocks of 2 MiB or more (then madvise MADV_HUGEPAGE).
    assert offset != 0


def test_a_users_own_setting_is_kept() -> None:
    poll, value, offset = _run_probe({"THP_MEM_ALLOC_ENABLE": "1", "RAY_TRAIN_HEALTH_CHECK_INTERVAL_S": "3"})
    assert value == "1" and poll == "3"
    assert offset == 0
