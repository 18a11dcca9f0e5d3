"""The weight average (``optim.ema_decay``): the average against one written out by hand, and its way through a
checkpoint: stored beside the live weights, read by every consumer of the checkpoint, restored on resume."""

from __future__ import annotations

from pathlib import Path

import torch
from train_fixtures import tiny_config, tiny_shards  # noqa: F401

from sray.platform.checkpoints.folders import load_checkpoint, write_checkpoint
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.train.state import build_training, restore_training, training_state
from sray.platform.train.weight_average import restore_average, weight_average


def _perturb(net: torch.nn.Module, generator: torch.Generator) -> None:
    """An optimiser step stand-in: random moves of every parameter."""
    with torch.no_grad():
        for p in net.parameters():
            p.add_(torch.randn(p.shape, generator=generator))


def test_the_average_follows_the_written_out_moving_average_and_survives_a_checkpoint(tiny_shards: Path,
                                                                                       tmp_path: Path) -> None:
    """After 4 updates the average is w1 then a <- d a + (1 - d) w_t, computed by hand; a checkpoint holds it
    beside the live weights, ``model_from_checkpoint`` (evaluation, finetuning, serving) loads the average, and
    a resume restores both the live weights and the average with its count."""
    cfg = tiny_config(tiny_shards, tmp_path)
    cfg.optim.ema_decay = 0.75
    wrapper, optimizer, scheduler = build_training(cfg)
    average = weight_average(wrapper.net, cfg.optim.ema_decay, "cpu")
    assert weight_average(wrapper.net, 0.0, "cpu") is None
    generator = torch.Generator().manual_seed(5)
    by_hand: dict[str, torch.Tensor] = {}
    for _ in range(4):
        _perturb(wrapper.net, generator)
        average.update_parameters(wrapper.net)
        for name, p in wrapper.net.named_parameters():
            by_hand[name] = p.detach().clone() if name not in by_hand else 0.75 * by_hand[name] + 0.25 * p.detach()
    averaged = dict(average.module.named_parameters())
    for name, want in by_hand.items():
        torch.testing.assert_close(averaged[name].detach(), want, rtol=1e-6, atol=1e-6, msg=name)
    live = {k: v.clone() for k, v in wrapper.net.state_dict().items()}
    assert any(not torch.equal(live[k], v) for k, v in average.module.state_dict().items())

    path = write_checkpoint(training_state(wrapper.net, optimizer, scheduler, None, 4, cfg, None, {}, average),
                            tmp_path / "ckpt" / "step_000000004", 4)
    served, _ = model_from_checkpoint(path)
    for key, value in average.module.state_dict().items():
        torch.testing.assert_close(served.state_dict()[key], value, rtol=0, atol=0, msg=key)

    other, opt2, sched2 = build_training(cfg)
    state = load_checkpoint(path)
    restore_training(state, other.net, opt2, sched2, None)
    resumed = weight_average(other.net, cfg.optim.ema_decay, "cpu")
    restore_average(state, resumed)
    assert int(resumed.n_averaged) == 4
    for key, value in live.items():
        torch.testing.assert_close(other.net.state_dict()[key], value, rtol=0, atol=0, msg=key)
    for key, value in average.module.state_dict().items():
        torch.testing.assert_close(resumed.module.state_dict()[key], value, rtol=0, atol=0, msg=key)


def test_a_checkpoint_without_an_average_serves_its_weights_and_starts_a_new_average_from_them(
        tiny_shards: Path, tmp_path: Path) -> None:
    """A job without the average writes no average entry and serves its live weights; turning the average on at a
    resume from such a checkpoint starts it from the weights of the first step it takes in."""
    cfg = tiny_config(tiny_shards, tmp_path)
    wrapper, optimizer, scheduler = build_training(cfg)
    state = training_state(wrapper.net, optimizer, scheduler, None, 2, cfg, None, {})
    assert "averaged_model" not in state
    served, _ = model_from_checkpoint(write_checkpoint(state, tmp_path / "plain" / "step_000000002", 2))
    for key, value in wrapper.net.state_dict().items():
        torch.testing.assert_close(served.state_dict()[key], value, rtol=0, atol=0, msg=key)
    average = weight_average(wrapper.net, 0.9, "cpu")
    restore_average(state, average)
    _perturb(wrapper.net, torch.Generator().manual_seed(6))
    average.update_parameters(wrapper.net)
    for key, value in wrapper.net.state_dict().items():
        torch.testing.assert_close(average.module.state_dict()[key], value, rtol=0, atol=0, msg=key)
