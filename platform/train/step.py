"""The one optimisation step of sray, shared by pretraining (``train_worker``) and per-scene finetuning. A step reads
top to bottom: seed -> (caller: forward under :meth:`TrainStep.autocast`, loss) -> backward (scaled under fp16) ->
unscale -> clip -> non-finite guard -> optimiser step -> scaler update -> zero grads. It waits for the device once: the
guard's flags (non-finite loss or gradient, a stop request from any rank) and the ranks' CPU seconds are summed over the
ranks in one transfer. Non-finite steps are skipped (no parameter or optimiser-state change), counted, and after
``max_nonfinite_in_row`` in a row the step raises :class:`NonFiniteTraining`."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import torch
from torch import Tensor, nn

PRECISIONS = {"no": None, "bf16": torch.bfloat16, "fp16": torch.float16}
"""Autocast dtype of each precision setting (``no`` = float32 throughout)."""


class NonFiniteTraining(RuntimeError):
    """Too many consecutive steps had a non-finite loss or gradient."""


def step_seed(seed: int, rank: int, step: int) -> int:
    """Seed of one step on one rank: a pure function, so a resumed job draws what an uninterrupted one would."""
    return (seed * 1_000_003 + rank * 7_919 + step) % (2**63 - 1)


@dataclass
class StepOutcome:
    """What one :class:`TrainStep` call did."""

    applied: bool
    """False when the step was skipped (non-finite loss or gradient)."""
    stop: bool
    grad_norm: Tensor
    """Total gradient norm before clipping, a device scalar (read it only when logging)."""
    cpu_seconds: float = 0.0
    """The CPU seconds the ranks passed to this step, summed over the ranks."""


class TrainStep:
    """Backward, clipping, non-finite guard, loss scaling and the update for one set of parameters."""

    def __init__(self, params: list[nn.Parameter], optimizer: torch.optim.Optimizer, grad_clip: float,
                 precision: str, device: torch.device, max_nonfinite_in_row: int, world_size: int = 1) -> None:
        if precision not in PRECISIONS:
            raise ValueError(f"precision {precision!r}: use one of {sorted(PRECISIONS)}")
        self.params, self.optimizer, self.grad_clip = params, optimizer, grad_clip
        self.precision, self.device, self.world_size = precision, device, world_size
        self.max_nonfinite_in_row = max_nonfinite_in_row
        self.scaler = torch.amp.GradScaler(device.type) if precision == "fp16" else None
        self.skipped_total = 0
        """Steps skipped so far (restored from checkpoints by the caller)."""
        self.skipped_in_row = 0

    def autocast(self) -> contextlib.AbstractContextManager:
        """The autocast region of this step's precision (forward and loss go inside it)."""
        dtype = PRECISIONS[self.precision]
        return torch.autocast(self.device.type, dtype=dtype, enabled=dtype is not None)

    def _gradient_norm(self, loss: Tensor) -> Tensor:
        """Total norm of the gradients before clipping (clips in place when ``grad_clip`` > 0)."""
        grads = [p for p in self.params if p.grad is not None]
        if not grads:
            return loss.detach().new_zeros(())
        if self.grad_clip > 0:
            return torch.nn.utils.clip_grad_norm_(grads, self.grad_clip)
        return torch.linalg.vector_norm(torch.stack([p.grad.norm() for p in grads]))

    def __call__(self, loss: Tensor, stop_requested: bool = False, cpu_seconds: float = 0.0) -> StepOutcome:
        """Apply one update from ``loss`` (a scalar with a graph); ``cpu_seconds``: this rank's CPU time so far."""
        (self.scaler.scale(loss) if self.scaler is not None else loss).backward()
        if self.scaler is not None:
            self.scaler.unscale_(self.optimizer)
        norm = self._gradient_norm(loss)
        bad = ~(torch.isfinite(norm) & torch.isfinite(loss.detach()))
        host = torch.tensor([float(stop_requested), cpu_seconds], dtype=torch.float64, device=norm.device)
        flags = torch.cat([bad.to(torch.float64).reshape(1), host])  # float64: CPU seconds stay exact
        if self.world_size > 1:
            torch.distributed.all_reduce(flags, op=torch.distributed.ReduceOp.SUM)  # a flag > 0: some rank set it
        nonfinite, stop, cpu_total = flags.tolist()  # the step's one device -> host transfer
        if not nonfinite:
            self.optimizer.step()
        if self.scaler is not None:
            self.scaler.update()
        self.optimizer.zero_grad(set_to_none=True)
        if nonfinite:
            self.skipped_total += 1
            self.skipped_in_row += 1
            if self.skipped_in_row >= self.max_nonfinite_in_row:
                raise NonFiniteTraining(
                    f"{self.skipped_in_row} steps in a row had a non-finite loss or gradient; lower the learning "
                    "rate, clip gradients harder, or train in precision 'no' or 'bf16'")
        else:
            self.skipped_in_row = 0
        return StepOutcome(applied=not nonfinite, stop=stop > 0, grad_norm=norm.detach(), cpu_seconds=cpu_total)


def fused_adam(params: list[nn.Parameter], lr: float) -> torch.optim.Optimizer:
    """Adam (the paper's optimiser), fused (CPU and CUDA): one kernel per step, no host reads of its counters."""
    return torch.optim.Adam(params, lr=lr, fused=True)
