"""``--set`` on the training config: types parsed from annotations, bad names listed, bad values rolled back."""

from __future__ import annotations

import pytest

from sray.jobs.recipes import get_recipe
from sray.platform.config.train_config import apply_override


def test_each_field_type_is_parsed_from_its_annotation() -> None:
    cfg = get_recipe("synth-small")
    for assignment in ("optim.lr=5e-4", "optim.steps=1_000", "model.geo_hidden=(64, 32)", "run.precision=bf16",
                       "data.shards=/x/y", "model.attention=cross"):
        apply_override(cfg, assignment)
    assert cfg.optim.lr == 5e-4 and cfg.optim.steps == 1000 and cfg.model.geo_hidden == (64, 32)
    assert cfg.run.precision == "bf16" and cfg.data.shards == "/x/y" and cfg.model.attention == "cross"


@pytest.mark.parametrize("assignment, message", [
    ("train.lr=1", "no section 'train'; sections: model, data, optim, run"),
    ("optim.nope=1", "no field 'nope' in OptimSettings"),
    ("model=1", "no field 'model' in TrainConfig"),
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
    apply_override(cfg, f"model.train_piece={cfg.data.rays_per_batch}")  # one piece: allowed
    with pytest.raises(ValueError, match="model.train_piece=0"):
        apply_override(cfg, "model.train_piece=64")
    assert cfg.model.train_piece == cfg.data.rays_per_batch
