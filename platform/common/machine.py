"""What a machine is, for every stored result: CPU model, cores, accelerator, and the training steps of a fixed probe
(:data:`PROBE_MODEL`, one seeded tiny batch) one CPU second buys on it, in a fresh one-thread process."""

from __future__ import annotations

import functools
import os
import platform as _stdlib_platform
import subprocess
import sys
import time
from pathlib import Path

import torch

from sray.model.config import SRayConfig
from sray.model.rays import pixel_rays
from sray.model.semantic_ray import SRayModel

PROBE_MODEL = SRayConfig(n_source=8, n_coarse=24, n_fine=24, attention="intra", lambda_src_sem=1.0)
"""The probe's network: ``synth-cpu-hour``'s model section when the probe was fixed."""
PROBE_RAYS = 64
PROBE_VIEWS = 8
PROBE_HW = (48, 64)
"""(H, W) of the probe's source images."""
PROBE_STEPS = 8
CPUINFO = Path("/proc/cpuinfo")


def cpu_model(cpuinfo: Path = CPUINFO) -> str:
    """The first ``model name`` of ``cpuinfo`` (Linux), else ``platform.processor()``, else the architecture."""
    if cpuinfo.exists():
        for line in cpuinfo.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                return value.strip()
    return _stdlib_platform.processor() or _stdlib_platform.machine()


def probe_batch() -> dict[str, torch.Tensor]:
    """The probe's fixed batch (seed 0): source images (V, 3, H, W) of cameras side by side looking along +z, their
    K (V, 3, 3) and c2w (V, 4, 4), and query rays (R, 3) with labels (R,) and colours (R, 3)."""
    h, w = PROBE_HW
    gen = torch.Generator().manual_seed(0)
    K = torch.tensor([[w / 2, 0.0, (w - 1) / 2], [0.0, w / 2, (h - 1) / 2], [0.0, 0.0, 1.0]])
    c2w = torch.eye(4).repeat(PROBE_VIEWS, 1, 1)
    c2w[:, 0, 3] = torch.linspace(-0.3, 0.3, PROBE_VIEWS)
    uv = torch.rand(PROBE_RAYS, 2, generator=gen) * torch.tensor([w - 1.0, h - 1.0])
    origins, dirs = pixel_rays(K, torch.eye(4), uv)
    return {"src_rgb": torch.rand(PROBE_VIEWS, 3, h, w, generator=gen), "src_K": K.expand(PROBE_VIEWS, 3, 3).clone(),
            "src_c2w": c2w, "origins": origins, "dirs": dirs, "rgb": torch.rand(PROBE_RAYS, 3, generator=gen),
            "label": torch.randint(0, PROBE_MODEL.n_classes, (PROBE_RAYS,), generator=gen)}


def probe_steps_per_cpu_second(steps: int = PROBE_STEPS) -> float:
    """Training steps of the probe (encode, render, loss, backward, Adam) per CPU second of this process."""
    state = torch.random.get_rng_state()
    try:
        torch.manual_seed(0)
        model = SRayModel(PROBE_MODEL)
        optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
        batch = probe_batch()

        def step() -> None:
            src = model.encode(batch["src_rgb"], batch["src_K"], batch["src_c2w"])
            loss, _ = model.training_loss(src, batch["origins"], batch["dirs"], 1.0, 5.0, batch["label"], batch["rgb"])
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()

        step()  # warm-up: first-call allocations and kernel choices
        start = time.process_time()
        for _ in range(steps):
            step()
        return steps / max(time.process_time() - start, 1e-9)
    finally:
        torch.random.set_rng_state(state)


def probe_in_fresh_process(steps: int = PROBE_STEPS, timeout_s: float = 300.0) -> float | None:
    """:func:`probe_steps_per_cpu_second` in a fresh one-thread process; None (with a warning) when it fails."""
    code = f"from sray.platform.common.machine import probe_steps_per_cpu_second as p; print(p({int(steps)}))"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    try:
        done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                              timeout=timeout_s, check=True)
        return float(done.stdout.strip().splitlines()[-1])
    except (subprocess.SubprocessError, OSError, ValueError, IndexError) as error:
        print(f"sray.platform.common.machine: the throughput probe failed ({error}); the machine descriptor stores "
              "ray_steps_per_cpu_second as null", file=sys.stderr)
        return None


@functools.lru_cache(maxsize=1)
def describe_machine() -> dict[str, str | int | float | None]:
    """``{"cpu_model", "cores", "device", "ray_steps_per_cpu_second"}`` (the probe's to 3 digits; None if it failed)."""
    rate = probe_in_fresh_process()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    device = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "cpu"
    return {"cpu_model": cpu_model(), "cores": cores, "device": device,
            "ray_steps_per_cpu_second": None if rate is None else float(f"{rate:.3g}")}
