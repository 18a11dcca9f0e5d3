"""The shared training step: one device -> host transfer per step, the non-finite guard, and an update
equal to plain Adam with clipping."""

from __future__ import annotations

import pytest
import torch
from torch.overrides import TorchFunctionMode

from sray.data_tools.loader.sample_types import QueryCamera, SourceViews, TrainSample
from sray.model.config import SRayConfig
from sray.model.ray_batch import RayBatchLoss
from sray.model.runtime import Runtime
from sray.platform.common.model_input import ray_batch
from sray.platform.train.step import NonFiniteTraining, TrainStep, fused_adam

H, W = 32, 40
HOST_READS = {"item", "tolist", "numpy", "cpu", "__bool__", "__float__", "__int__", "__index__", "nonzero",
              "masked_select", "argwhere", "unique", "equal", "allclose"}
"""Tensor calls that make the host wait for the device (on a GPU: a synchronisation)."""


class HostReadCounter(TorchFunctionMode):
    """Counts tensor -> host conversions, boolean-mask indexing and explicit copies to the host while active.

    On this CPU-only test the training device is the CPU too, so moves to the training device
    (``.to(device)``) are not host reads; an explicit ``.to("cpu")`` is."""

    def __init__(self) -> None:
        super().__init__()
        self.reads: list[str] = []

    def __torch_function__(self, func, types, args=(), kwargs=None):  # noqa: ANN001 - torch's protocol
        kwargs = kwargs or {}
        name = getattr(func, "__name__", str(func))
        if name in HOST_READS:
            self.reads.append(name)
        elif name == "__getitem__" and _has_bool_tensor(args[1]):
            self.reads.append("boolean-mask indexing")
        elif name == "to" and "cpu" in (*args[1:], *kwargs.values()):  # an explicit copy to the host
            self.reads.append("to('cpu')")
        return func(*args, **kwargs)


def _has_bool_tensor(index: object) -> bool:
    items = index if isinstance(index, tuple) else (index,)
    return any(torch.is_tensor(i) and i.dtype == torch.bool for i in items)


def _batch(seed: int = 0) -> TrainSample:
    """A training sample as the loader makes it: 3 sources, 64 rays, some unlabelled."""
    g = torch.Generator().manual_seed(seed)
    K = torch.tensor([[28.0, 0.0, (W - 1) / 2], [0.0, 28.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
    c2w = torch.eye(4).expand(3, 4, 4).clone()
    c2w[:, 0, 3] = torch.tensor([-0.2, 0.0, 0.2])
    labels = torch.randint(0, 5, (64,), generator=g)
    labels[::7] = 255
    sources = SourceViews(rgb=torch.rand(3, 3, H, W, generator=g), K=K.expand(3, 3, 3).clone(), c2w=c2w)
    return TrainSample(scene="s", query_id="q", sources=sources, query=QueryCamera(K=K, c2w=torch.eye(4)),
                       near=1.0, far=4.0, pixels=torch.rand(64, 2, generator=g) * torch.tensor([W - 1.0, H - 1.0]),
                       target_label=labels, target_rgb=torch.rand(64, 3, generator=g))


def _setup(precision: str = "no", lr: float = 1e-3) -> tuple[RayBatchLoss, TrainStep]:
    torch.manual_seed(0)
    pieces = Runtime(train_piece=16)  # 4 pieces of the 64 rays
    model = RayBatchLoss(SRayConfig(n_classes=5, n_coarse=6, n_fine=6, n_source=3), pieces).train()
    params = list(model.parameters())
    return model, TrainStep(params, fused_adam(params, lr), 1.0, precision, torch.device("cpu"), 3)


def _loss(model: RayBatchLoss, step: TrainStep, sample: TrainSample) -> torch.Tensor:
    with step.autocast():
        loss, _ = model(ray_batch(sample), sample.target_label, sample.target_rgb)
    return loss


@pytest.mark.parametrize("precision", ["no", "bf16"])
def test_a_training_step_reads_the_device_once(precision: str) -> None:
    model, step = _setup(precision)
    batch = _batch()
    _loss(model, step, batch)  # warm-up (lazy initialisations)
    counter = HostReadCounter()
    with counter:
        outcome = step(_loss(model, step, batch), stop_requested=False)
    assert outcome.applied and not outcome.stop
    assert counter.reads == ["tolist"], counter.reads


def test_the_counter_sees_the_reads_it_claims_to_count() -> None:
    """The counting mode itself must not be blind (else the test above could not fail)."""
    counter = HostReadCounter()
    t = torch.arange(4.0)
    with counter:
        bool(t.sum() > 0)
        float(t[0])
        t.item() if t.numel() == 1 else t[0].item()
        _ = t[t > 1]
        t.cpu()
    assert counter.reads == ["__bool__", "__float__", "item", "boolean-mask indexing", "cpu"]


def test_a_non_finite_loss_changes_nothing_and_too_many_in_a_row_stop_training() -> None:
    model, step = _setup()
    batch = _batch()
    step(_loss(model, step, batch))  # one real step so the optimiser has state
    params = {k: v.detach().clone() for k, v in model.state_dict().items()}
    moments = {k: v.clone() for k, v in step.optimizer.state_dict()["state"][0].items()}
    for i in range(2):
        outcome = step(_loss(model, step, batch) * float("nan"))
        assert not outcome.applied and step.skipped_total == i + 1
    for k, v in model.state_dict().items():
        torch.testing.assert_close(v, params[k], rtol=0, atol=0)
    for k, v in step.optimizer.state_dict()["state"][0].items():
        torch.testing.assert_close(v, moments[k], rtol=0, atol=0)
    assert all(p.grad is None for p in model.parameters())
    with pytest.raises(NonFiniteTraining, match="3 steps in a row"):
        step(_loss(model, step, batch) * float("inf"))


def test_the_update_equals_plain_adam_after_clipping() -> None:
    """Reference: the plain torch sequence backward -> clip_grad_norm_ -> Adam.step, one after the other."""
    model, step = _setup(lr=1e-2)
    reference, _ = _setup(lr=1e-2)
    ref_opt = torch.optim.Adam(reference.parameters(), lr=1e-2, fused=True)
    for seed in range(3):
        batch = _batch(seed)
        torch.manual_seed(seed)
        outcome = step(_loss(model, step, batch))
        torch.manual_seed(seed)
        ref_loss = _loss(reference, step, batch)
        ref_loss.backward()
        ref_norm = torch.nn.utils.clip_grad_norm_(reference.parameters(), 1.0)
        ref_opt.step()
        ref_opt.zero_grad()
        torch.testing.assert_close(outcome.grad_norm, ref_norm, rtol=1e-5, atol=1e-6, msg=f"step {seed}")
    for (name, got), want in zip(model.state_dict().items(), reference.state_dict().values()):
        torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-6, msg=name)
