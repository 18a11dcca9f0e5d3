"""The workloads ``sray bench model`` and ``sray bench profile`` time: a training step and a whole-image render.

Both run on a synthetic scene (random source images, a camera rig whose sources all look at the
query's frustum), so they need no data and measure the model alone. A spec dict names the sizes:
rays, coarse, fine, views, hw, device, and optionally dtype ('fp32'|'bf16'|'fp16'), impl
('reference'|'fast', ``Runtime.impl``), fine_samples ('union'|'new'; absent = the model default),
piece (rays per piece of the training loss, ``Runtime.train_piece``; 0 = by device), chunk (rays per
render chunk, ``Runtime.chunk``; absent = by device), compile (both fields through ``torch.compile``), model (any other
``SRayConfig`` fields, e.g. a recipe's whole model section), steps. With ``inputs='rgbd'`` (in ``model``)
the sources get depth maps.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import torch

from sray.jobs.bench.probes import peak_rss_bytes, timed_runs
from sray.model.config import SRayConfig
from sray.model.rays import pixel_rays
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel
from sray.platform.train.step import fused_adam


def synthetic_batch(rays: int, views: int, hw: tuple[int, int], device: torch.device, depth: bool = False) -> dict:
    """Random source images (m, 3, H, W), their cameras, ``rays`` query rays, labels and colours; with
    ``depth``, source z-depth maps (m, H, W) in [1.5, 4.5] metres (inside the workloads' near 1, far 5)."""
    h, w = hw
    gen = torch.Generator().manual_seed(0)
    K = torch.tensor([[w / 2, 0.0, (w - 1) / 2], [0.0, w / 2, (h - 1) / 2], [0.0, 0.0, 1.0]])
    c2w = torch.eye(4).repeat(views, 1, 1)
    c2w[:, 0, 3] = torch.linspace(-0.3, 0.3, views)
    c2w[:, 1, 3] = 0.1 * torch.sin(torch.arange(views, dtype=torch.float32))
    uv = torch.rand(rays, 2, generator=gen) * torch.tensor([w - 1.0, h - 1.0])
    origins, dirs = pixel_rays(K, torch.eye(4), uv)
    batch = {"src_rgb": torch.rand(views, 3, h, w, generator=gen), "src_K": K.expand(views, 3, 3).clone(),
             "src_c2w": c2w, "origins": origins, "dirs": dirs, "K": K,
             "label": torch.randint(0, 20, (rays,), generator=gen), "rgb": torch.rand(rays, 3, generator=gen)}
    if depth:
        batch["src_depth"] = 1.5 + 3.0 * torch.rand(views, h, w, generator=gen)
    return {k: v.to(device) for k, v in batch.items()}


def model_config(spec: dict) -> SRayConfig:
    """The ``SRayConfig`` of a workload spec: its ``model`` fields, then its sizes and fine_samples (paper
    defaults for everything the spec leaves out)."""
    cfg = SRayConfig(**spec.get("model", {}))
    return dataclasses.replace(cfg, n_coarse=spec["coarse"], n_fine=spec["fine"], n_source=spec["views"],
                               fine_samples=spec.get("fine_samples", cfg.fine_samples))


def spec_runtime(spec: dict) -> Runtime:
    """The ``Runtime`` of a workload spec: its impl, piece and chunk (the defaults for what it leaves out or
    sets to 0)."""
    fields = {"impl": "impl", "piece": "train_piece", "chunk": "chunk"}
    return Runtime(**{field: spec[key] for key, field in fields.items() if spec.get(key)})


def make_train_step(spec: dict) -> Callable[[], None]:
    """A closure running one full training step (encode, render, loss, backward, Adam) of ``spec``."""
    device = torch.device(spec["device"])
    torch.manual_seed(0)
    cfg, runtime = model_config(spec), spec_runtime(spec)
    model = SRayModel(cfg).to(device)
    if spec.get("compile"):
        model.coarse.compile()
        model.fine.compile()
    opt = fused_adam(list(model.parameters()), 1e-3)  # the optimizer training uses
    batch = synthetic_batch(spec["rays"], spec["views"], tuple(spec["hw"]), device, depth=cfg.inputs == "rgbd")
    dtype = {"fp32": None, "bf16": torch.bfloat16, "fp16": torch.float16}[spec.get("dtype", "fp32")]
    scaler = torch.amp.GradScaler(device.type, enabled=dtype == torch.float16)

    def step() -> None:
        with torch.autocast(device.type, dtype=dtype or torch.float32, enabled=dtype is not None):
            src = model.encode(batch["src_rgb"], batch["src_K"], batch["src_c2w"], batch.get("src_depth"))
            loss, _ = model.training_loss(src, batch["origins"], batch["dirs"], 1.0, 5.0, batch["label"], batch["rgb"],
                                          runtime)
        opt.zero_grad(set_to_none=True)
        scaler.scale(loss).backward()
        scaler.step(opt)
        scaler.update()
        if not torch.isfinite(loss):
            raise FloatingPointError(f"sray.jobs.bench.workloads: non-finite loss in {spec}.")

    step.n_params = sum(p.numel() for p in model.parameters())  # type: ignore[attr-defined]
    return step


def render_case(spec: dict) -> Callable[[], None]:
    """A closure rendering one whole (H, W) view of the synthetic scene with ``render_image`` (no grad)."""
    device = torch.device(spec["device"])
    torch.manual_seed(0)
    model, runtime = SRayModel(model_config(spec)).to(device).eval(), spec_runtime(spec)
    h, w = spec["hw"]
    batch = synthetic_batch(1, spec["views"], (h, w), device)
    with torch.no_grad():
        src = model.encode(batch["src_rgb"], batch["src_K"], batch["src_c2w"])
    query = torch.eye(4, device=device)

    def render() -> None:
        model.render_image(src, batch["K"], query, (h, w), 1.0, 5.0, runtime)
    return render


def train_step_worker(spec: dict) -> dict:
    """Time ``spec["steps"]`` training steps after a warm-up one; meant for a fresh process.

    Returns the first step's time (warm-up, compilation included), the median of the following
    steps, the process peak RSS and the GPU allocator peak. ``alloc='thp'`` in the spec needs
    THP_MEM_ALLOC_ENABLE=1 set by the parent before this process starts.
    """
    device = torch.device(spec["device"])
    step = make_train_step(spec)
    times = timed_runs(step, device, int(spec["steps"]) + 1)
    peak_gpu = int(torch.cuda.max_memory_allocated(device)) if device.type == "cuda" else 0
    rest = sorted(times[1:])
    return {"first": times[0], "seconds": rest[len(rest) // 2], "rss_bytes": peak_rss_bytes(),
            "gpu_peak_bytes": peak_gpu, "params": step.n_params}  # type: ignore[attr-defined]
