"""``--set`` on the training config: types parsed from annotations, bad names listed, bad values rolled back."""

from __future__ import annotations


import pytest

from sray.data_tools.loader.augment import Augmentation
from sray.model.runtime import Runtime
from sray.platform.config.recipes import get_recipe
from sray.platform.config.train_config import apply_override


def test_each_field_type_is_parsed_from_its_annotation() -> None:
    cfg = get_recipe("synth-small")
    for assignment in ("optim.lr=5e-4", "optim.steps=1_000", "model.geo_hidden=(64, 32)", "run.precision=bf16",
                       "data.shards=/x/y", "model.attention=cross"):
        apply_override(cfg, assignment)
    assert cfg.optim.lr == 5e-4 and cfg.optim.steps == 1000 and cfg.model.geo_hidden == (64, 32)
    assert cfg.run.precision == "bf16" and cfg.data.shards == "/x/y" and cfg.model.attention == "cross"


@pytest.mark.parametrize("assignment, message", [
    ("train.lr=1", "no section 'train'; sections: model, data, optim, run, runtime"),
    ("optim.nope=1", "no field 'nope' in OptimSettings"),
    ("model=1", "no field 'model' in TrainConfig; 'model' is a section: set its fields, model.<field>"),
    ("data.aug=0.3", "'aug' is a section: set its fields, data.aug.<field> with <field> one of channel_ev, colour_ev"),
    ("optim.steps=many", "not a valid int"),
    ("optim.lr", "expected"),
])
def test_bad_assignments_name_what_is_wrong(assignment: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        apply_override(get_recipe("synth-small"), assignment)


def test_a_value_the_network_rejects_leaves_the_config_as_it_was() -> None:
    cfg = get_recipe("synth-small")
    heads, attention = cfg.model.n_heads, cfg.model.attention
    with pytest.raises(ValueError, match="n_heads"):
        apply_override(cfg, "model.n_heads=7")
    assert cfg.model.n_heads == heads
    with pytest.raises(ValueError, match="attention"):
        apply_override(cfg, "model.attention=sparse")
    assert cfg.model.attention == attention


def test_fp16_with_a_loss_in_pieces_is_refused_and_rolled_back() -> None:
    """fp16 scales the loss, not a piece's own gradients: pieces smaller than the batch are refused."""
    cfg = get_recipe("synth-small")
    apply_override(cfg, "run.precision=fp16")
    apply_override(cfg, f"runtime.train_piece={cfg.data.rays_per_batch}")  # one piece: allowed
    with pytest.raises(ValueError, match="runtime.train_piece=0"):
        apply_override(cfg, "runtime.train_piece=64")
    assert cfg.runtime.train_piece == cfg.data.rays_per_batch


def test_augmentation_is_set_field_by_field_in_the_data_aug_section() -> None:
    cfg = get_recipe("synth-small")
    apply_override(cfg, "data.aug.colour_ev=0.3")
    apply_override(cfg, "data.aug.min_source=2")
    assert cfg.data.aug == Augmentation(colour_ev=0.3, min_source=2)
    with pytest.raises(ValueError, match="source_scale"):
        apply_override(cfg, "data.aug.source_scale=1.0")
    assert cfg.data.aug == Augmentation(colour_ev=0.3, min_source=2)  # the rejected value left no trace
    with pytest.raises(ValueError, match="no field 'colour' in Augmentation; fields: channel_ev, colour_ev"):
        apply_override(cfg, "data.aug.colour=0.3")


def test_runtime_settings_are_set_in_the_runtime_section_and_checked() -> None:
    cfg = get_recipe("synth-small")
    apply_override(cfg, "runtime.impl=reference")
    apply_override(cfg, "runtime.chunk=4096")
    assert cfg.runtime == Runtime(impl="reference", chunk=4096)
    with pytest.raises(ValueError, match="impl"):
        apply_override(cfg, "runtime.impl=slow")
    assert cfg.runtime == Runtime(impl="reference", chunk=4096)  # the rejected value left no trace
    before = cfg.to_dict()
    with pytest.raises(ValueError, match="no field 'chunk' in SRayConfig"):
        apply_override(cfg, "model.chunk=256")
    assert cfg.to_dict() == before
