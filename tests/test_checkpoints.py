"""Checkpoints: exact resume, weights_only loading, atomic saves, latest/best bookkeeping, Ray wrapping."""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest
import torch
from rng_state import capture_rng, restore_rng
from torch import nn

from sray.platform.checkpoints import folders as checkpoints
from sray.platform.checkpoints.folders import CheckpointManager, check_weights_only_safe, load_checkpoint
from sray.platform.train.worker import from_ray_checkpoint, to_ray_checkpoint


def _build(seed: int):
    """A tiny model with dropout (consumes torch RNG), AdamW, a warm-up+cosine schedule, a scaler."""
    torch.manual_seed(seed)
    model = nn.Sequential(nn.Linear(4, 16), nn.ReLU(), nn.Dropout(0.3), nn.Linear(16, 3))
    opt = torch.optim.AdamW(model.parameters(), lr=1e-2, weight_decay=0.01)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=1e-2, total_steps=20)
    scaler = torch.amp.GradScaler("cpu", init_scale=2.0 ** 8)
    return model, opt, sched, scaler


def _step(model, opt, sched, scaler) -> None:
    """One step whose batch comes from Python's and NumPy's global RNGs (so all three must resume)."""
    n = random.randint(3, 6)
    x = torch.from_numpy(np.random.standard_normal((n, 4)).astype(np.float32))
    y = torch.tensor([random.randrange(3) for _ in range(n)])
    loss = nn.functional.cross_entropy(model(x), y)
    opt.zero_grad()
    scaler.scale(loss).backward()
    scaler.step(opt)
    scaler.update()
    sched.step()


def _state(model, opt, sched, scaler, step: int) -> dict:
    return {"model": model.state_dict(), "optimizer": opt.state_dict(), "scheduler": sched.state_dict(),
            "scaler": scaler.state_dict(), "step": step, "rng": capture_rng(),
            "config": {"lr": 1e-2, "data": {"root": "/tmp/x"}, "views": [1, 2]}, "best_metric": 0.25}


def _seed_all(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def test_resume_continues_exactly_like_an_uninterrupted_run(tmp_path):
    _seed_all(0)
    reference = _build(1)
    for _ in range(8):
        _step(*reference)

    _seed_all(0)
    first = _build(1)
    for _ in range(4):
        _step(*first)
    manager = CheckpointManager(tmp_path / "ckpt")
    manager.save(_state(*first, step=4), step=4)
    _seed_all(123)  # the restarted process starts from other RNG states and other weights
    resumed = _build(99)
    _step(*resumed)
    state = load_checkpoint(manager.latest())
    resumed[0].load_state_dict(state["model"])
    resumed[1].load_state_dict(state["optimizer"])
    resumed[2].load_state_dict(state["scheduler"])
    resumed[3].load_state_dict(state["scaler"])
    restore_rng(state["rng"])
    assert state["step"] == 4
    for _ in range(4):
        _step(*resumed)

    for (name, a), (_, b) in zip(reference[0].state_dict().items(), resumed[0].state_dict().items()):
        torch.testing.assert_close(b, a, rtol=0, atol=0, msg=f"parameter {name} differs after resume")
    assert resumed[2].get_last_lr() == reference[2].get_last_lr()


def test_state_loads_with_weights_only_and_keeps_every_field(tmp_path):
    parts = _build(0)
    _step(*parts)
    state = _state(*parts, step=1)
    path = CheckpointManager(tmp_path).save(state, step=1, metric=0.5)
    loaded = torch.load(path / checkpoints.STATE_FILE, weights_only=True)
    assert set(loaded) == set(state)
    assert loaded["config"] == state["config"] and loaded["step"] == 1
    for key, value in state["model"].items():
        torch.testing.assert_close(loaded["model"][key], value, rtol=0, atol=0)
    assert isinstance(loaded["rng"]["python"]["internal"], list)


def test_rng_round_trip_reproduces_every_generator():
    _seed_all(5)
    saved = capture_rng()
    expected = (random.random(), float(np.random.standard_normal()), torch.rand(3))
    _seed_all(6)
    restore_rng(saved)
    got = (random.random(), float(np.random.standard_normal()), torch.rand(3))
    assert got[:2] == expected[:2]
    torch.testing.assert_close(got[2], expected[2], rtol=0, atol=0)


@pytest.mark.parametrize("bad, where", [({"a": np.zeros(2)}, "state['a']"), ({"p": Path("/x")}, "state['p']"),
                                        ({"m": [1, np.float64(2.0)]}, "state['m'][1]")])
def test_unsafe_values_are_named_before_writing(tmp_path, bad, where):
    with pytest.raises(TypeError, match=r"weights_only") as err:
        CheckpointManager(tmp_path).save(bad, step=1)
    assert str(err.value).startswith(where)
    assert CheckpointManager(tmp_path).latest() is None


def test_crash_during_save_leaves_previous_latest_intact(tmp_path, monkeypatch):
    manager = CheckpointManager(tmp_path)
    manager.save({"w": torch.ones(3), "step": 10}, step=10)

    def crashing_save(obj, f):
        f.write(b"partial bytes of a checkpoint")
        raise OSError("disk full")

    monkeypatch.setattr(checkpoints.torch, "save", crashing_save)
    for step in (20, 10):  # a new step, and a repeated step replacing the existing folder
        with pytest.raises(OSError, match="disk full"):
            manager.save({"w": torch.zeros(3), "step": step}, step=step)
        assert manager.latest() == tmp_path / "step_000000010"
        torch.testing.assert_close(load_checkpoint(manager.latest())["w"], torch.ones(3), rtol=0, atol=0)
    assert [p.name for p in tmp_path.iterdir()] == ["step_000000010"]


def test_interrupted_replacement_is_recovered_on_restart(tmp_path):
    manager = CheckpointManager(tmp_path)
    manager.save({"step": 7}, step=7)
    (tmp_path / "step_000000007").rename(tmp_path / ".old-step_000000007-123-abcdef12")  # killed mid-swap
    (tmp_path / ".tmp-step_000000008-123-abcdef12").mkdir()  # and an abandoned temp folder
    recovered = CheckpointManager(tmp_path)
    assert recovered.latest() == tmp_path / "step_000000007"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["step_000000007"]


def test_latest_best_and_pruning(tmp_path):
    manager = CheckpointManager(tmp_path, keep_last=2)
    metrics = {100: 0.30, 200: 0.55, 300: 0.41, 400: None, 500: 0.55, 600: 0.20}
    for step, metric in metrics.items():
        manager.save({"step": step}, step=step, metric=metric)
    assert manager.latest() == tmp_path / "step_000000600"
    assert manager.best() == tmp_path / "step_000000200"  # ties keep the earliest
    assert [s for s, _, _ in manager.entries()] == [200, 500, 600]
    assert load_checkpoint(manager.best())["step"] == 200

    scored = CheckpointManager(tmp_path / "nan", keep_last=1)  # a non-finite metric is stored as none
    for step, metric in ((1, 1.0), (2, 3.0), (3, float("nan")), (4, 2.0)):
        scored.save({"step": step}, step=step, metric=metric)
    assert scored.best() == tmp_path / "nan" / "step_000000002"
    assert [s for s, _, _ in scored.entries()] == [2, 4]


def test_empty_manager_and_bad_folders_give_clear_errors(tmp_path):
    manager = CheckpointManager(tmp_path)
    assert manager.latest() is None and manager.best() is None
    with pytest.raises(FileNotFoundError, match="state.pt"):
        load_checkpoint(tmp_path)
    with pytest.raises(ValueError):
        CheckpointManager(tmp_path, keep_last=0)


def test_ray_checkpoint_round_trip(tmp_path):
    path = CheckpointManager(tmp_path / "local").save({"w": torch.arange(4.0), "step": 3}, step=3, metric=0.1)
    ray_ckpt = to_ray_checkpoint(path)
    copied = Path(ray_ckpt.to_directory(str(tmp_path / "restored")))  # as Ray does on another node
    assert sorted(p.name for p in copied.iterdir()) == sorted([checkpoints.STATE_FILE, checkpoints.META_FILE])
    state = from_ray_checkpoint(ray_ckpt)
    torch.testing.assert_close(state["w"], torch.arange(4.0), rtol=0, atol=0)
    with pytest.raises(FileNotFoundError, match="meta.json"):
        to_ray_checkpoint(tmp_path)


def test_check_accepts_real_training_state():
    parts = _build(0)
    _step(*parts)
    check_weights_only_safe(_state(*parts, step=1))


def test_initial_checkpoint_is_the_seeded_untrained_model_at_step_0(tmp_path: Path) -> None:
    from sray.platform.config.recipes import get_recipe
    from sray.model.semantic_ray import SRayModel
    from sray.platform.train.state import write_initial_checkpoint

    cfg = get_recipe("synth-small")
    cfg.model.n_coarse, cfg.model.n_fine, cfg.run.seed = 4, 4, 3
    state = checkpoints.load_checkpoint(write_initial_checkpoint(cfg, tmp_path / "ck"))
    assert state["step"] == 0 and state["config"]["run"]["seed"] == 3
    torch.manual_seed(3)  # the model a fresh job seeded with 3 starts from, built independently here
    expected = SRayModel(cfg.model).state_dict()
    assert state["model"].keys() == expected.keys()
    assert all(torch.equal(state["model"][k], v) for k, v in expected.items())
    cfg.run.seed = 4
    other = checkpoints.load_checkpoint(write_initial_checkpoint(cfg, tmp_path / "other"))
    assert not all(torch.equal(other["model"][k], v) for k, v in expected.items())
