"""Training checkpoints hold the bare model's keys; checkpoints of the old ``net.``-prefixed form still load, and so
do checkpoints and job configs whose data section holds the augmentation settings flat (``aug_<field>``) or whose
model section holds the runtime settings."""

from __future__ import annotations

from pathlib import Path

import json

import torch
from train_fixtures import tiny_config, tiny_shards  # noqa: F401

from sray.data_tools.loader.augment import Augmentation
from sray.model.runtime import Runtime
from sray.platform.checkpoints.folders import load_checkpoint, write_checkpoint
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.config.train_config import CONFIG_FILE, load_job_config
from sray.platform.train.state import build_training, restore_training, training_state


def test_new_checkpoints_hold_bare_keys_and_legacy_ones_still_load(tiny_shards: Path, tmp_path: Path) -> None:
    cfg = tiny_config(tiny_shards, tmp_path)
    wrapper, optimizer, scheduler = build_training(cfg)
    with torch.no_grad():  # weights no fresh build can have, so a load that did nothing would show
        for p in wrapper.parameters():
            p.add_(torch.randn_like(p))
    state = training_state(wrapper.net, optimizer, scheduler, None, 3, cfg, None, {})
    assert set(state["model"]) == set(wrapper.net.state_dict())  # no "net." prefix
    new = write_checkpoint(state, tmp_path / "new" / "step_000000003", 3)

    legacy_state = dict(state, model=wrapper.state_dict())  # the old form: the wrapper's keys
    assert all(k.startswith("net.") for k in legacy_state["model"])
    legacy = write_checkpoint(legacy_state, tmp_path / "legacy" / "step_000000003", 3)

    for path in (new, legacy):
        net, _ = model_from_checkpoint(path)
        for key, value in wrapper.net.state_dict().items():
            torch.testing.assert_close(net.state_dict()[key], value, rtol=0, atol=0)
        other, opt2, sched2 = build_training(cfg)
        step, _, _ = restore_training(load_checkpoint(path), other.net, opt2, sched2, None)
        assert step == 3
        for key, value in wrapper.net.state_dict().items():
            torch.testing.assert_close(other.net.state_dict()[key], value, rtol=0, atol=0)


def test_checkpoints_and_job_configs_with_flat_augmentation_keys_load_into_data_aug(tiny_shards: Path,
                                                                                    tmp_path: Path) -> None:
    cfg = tiny_config(tiny_shards, tmp_path)
    wrapper, optimizer, scheduler = build_training(cfg)
    state = training_state(wrapper.net, optimizer, scheduler, None, 3, cfg, None, {})
    del state["config"]["data"]["aug"]
    state["config"]["data"].update(aug_colour_ev=0.3, aug_channel_ev=0.1, aug_noise_sigma=3.0, aug_min_source=2,
                                   aug_source_scale=0.25, aug_query_crop=0.0)  # the flat form
    expected = Augmentation(colour_ev=0.3, channel_ev=0.1, noise_sigma=3.0, min_source=2, source_scale=0.25)

    _, loaded = model_from_checkpoint(write_checkpoint(state, tmp_path / "flat" / "step_000000003", 3))
    assert loaded.data.aug == expected and loaded.data.top_k == cfg.data.top_k
    (tmp_path / "jobs" / "flat-job").mkdir(parents=True)
    (tmp_path / "jobs" / "flat-job" / CONFIG_FILE).write_text(json.dumps(state["config"]))
    assert load_job_config(str(tmp_path / "jobs"), "flat-job").data.aug == expected  # sray train --resume


def test_checkpoints_hold_the_network_and_its_loss_and_ones_with_runtime_fields_in_the_model_section_load(
        tiny_shards: Path, tmp_path: Path) -> None:
    """A new checkpoint's model section holds no runtime field (they are the job's ``runtime`` section); a
    checkpoint whose model section holds them (``impl``, ``chunk``, ``train_piece``) loads the same weights and
    reads them into ``runtime``."""
    cfg = tiny_config(tiny_shards, tmp_path)
    wrapper, optimizer, scheduler = build_training(cfg)
    state = training_state(wrapper.net, optimizer, scheduler, None, 3, cfg, None, {})
    assert not {"impl", "chunk", "train_piece"} & set(state["config"]["model"])
    assert state["config"]["runtime"] == {"impl": "fast", "chunk": 1024, "train_piece": 24}
    old = dict(state["config"])
    old["model"] = {**old["model"], **old.pop("runtime"), "impl": "reference"}  # the runtime in the model section

    path = write_checkpoint(dict(state, config=old), tmp_path / "old" / "step_000000003", 3)
    net, loaded = model_from_checkpoint(path)
    assert loaded.runtime == Runtime(impl="reference", chunk=1024, train_piece=24) and loaded.model == cfg.model
    for key, value in wrapper.net.state_dict().items():
        torch.testing.assert_close(net.state_dict()[key], value, rtol=0, atol=0)
