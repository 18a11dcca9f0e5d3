"""Held-out renders inside jobs (validation, the fleet): the fast mode by default, the full render one setting
away, bad values refused by name, and the protocol descriptor saying which render made the scores."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from fleet_fixtures import tiny_checkpoint, tiny_fleet_config  # noqa: F401
from train_fixtures import tiny_config, tiny_shards  # noqa: F401

from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.model.fast_render import FastRender
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.config.fleet_config import check_fleet_config
from sray.platform.config.held_out_render import held_out_fast
from sray.platform.config.train_config import apply_override
from sray.platform.eval.view_scoring import predict_view, sray_renderer
from sray.platform.finetune.learners import SRayLearner
from sray.platform.train.validation import validation_protocol


def test_fast_renders_the_evaluations_own_pixels_and_bad_values_name_the_field() -> None:
    assert held_out_fast("fast", 0.8, "f.render") == FastRender(pixel_stride=1, confidence=0.8)
    assert held_out_fast("full", 0.8, "f.render") is None
    with pytest.raises(ValueError, match=r"f\.render is 'quick'; use one of \('fast', 'full'\)"):
        held_out_fast("quick", 0.9, "f.render")
    with pytest.raises(ValueError, match=r"f\.fast_confidence is 0\.0; it must be > 0"):
        held_out_fast("fast", 0.0, "f.render")


def test_train_and_fleet_configs_refuse_a_bad_render_and_keep_their_value(tiny_shards: Path, tmp_path: Path) -> None:
    cfg = tiny_config(tiny_shards, tmp_path)
    with pytest.raises(ValueError, match="data.val_render is 'quick'"):
        apply_override(cfg, "data.val_render=quick")
    assert cfg.data.val_render == "fast"
    apply_override(cfg, "data.val_render=full")
    assert validation_protocol(cfg).render == "full"
    apply_override(cfg, "data.val_fast_confidence=0.7")
    apply_override(cfg, "data.val_render=fast")
    assert validation_protocol(cfg).render == FastRender(1, 0.7).describe()
    fleet = tiny_fleet_config(eval_render="nope")
    with pytest.raises(ValueError, match="finetune.eval_render is 'nope'"):
        check_fleet_config(fleet)


@pytest.mark.parametrize("render", ["fast", "full"])
def test_the_finetune_learners_held_out_renderer_is_the_chosen_render(tiny_checkpoint: Path, tiny_shards: Path,
                                                                      render: str) -> None:
    """With the encoder frozen the learner reuses encoded sources; its views equal a fresh ``sray_renderer``
    of the same mode, and the fast views differ from the full ones (the render really changed). The fast
    mode's threshold is one every coarse ray reaches: with no fine pass its views are the coarse pass's,
    while a fine pass on every ray would equal the full render (both evaluate the resampled depths only)."""
    net, _ = model_from_checkpoint(tiny_checkpoint)
    fast = held_out_fast(render, 1e-3, "finetune.eval_render")
    learner = SRayLearner(net, "sha", ("coarse.classifier",), 1e-3, 1.0, "no", torch.device("cpu"), 5, fast)
    assert learner.encoder_frozen and learner.fast == fast
    sample = next(iter(make_eval_samples(tiny_shards, "synth_test_000", split="test", n_source=3)))
    with torch.no_grad():
        got = predict_view(learner.renderer(sample), sample, 2, 512, torch.device("cpu"), learner.fast)
        again = predict_view(learner.renderer(sample), sample, 2, 512, torch.device("cpu"), learner.fast)  # cached
        want = predict_view(sray_renderer(net, sample, torch.device("cpu"), fast), sample, 2, 512,
                           torch.device("cpu"), fast)
        full = predict_view(sray_renderer(net, sample, torch.device("cpu")), sample, 2, 512, torch.device("cpu"))
    for view in (got, again):
        torch.testing.assert_close(view.pred_rgb, want.pred_rgb, rtol=0, atol=0)
        assert torch.equal(view.pred_label, want.pred_label)
    assert (render == "full") == torch.equal(got.pred_rgb, full.pred_rgb)


def test_a_render_grid_too_coarse_for_a_small_image_shrinks_to_fit(tiny_checkpoint: Path, tiny_shards: Path) -> None:
    """32x40 views scored every 8th pixel: pixel stride 8 would put the first ray at pixel 32, outside the
    image; the render uses the largest stride that fits (7), exactly as if it had been asked for."""
    eight = FastRender(8)
    assert eight.fitted_pixel_stride(8, (32, 40)) == 7 and eight.fitted_pixel_stride(1, (240, 320)) == 8
    assert eight.fitted_pixel_stride(64, (32, 40)) == 1
    net, _ = model_from_checkpoint(tiny_checkpoint)
    sample = next(iter(make_eval_samples(tiny_shards, "synth_test_000", split="test", n_source=3)))
    cpu = torch.device("cpu")
    views = [predict_view(sray_renderer(net, sample, cpu, f), sample, 8, 512, cpu, f)
             for f in (FastRender(8, 0.9), FastRender(7, 0.9))]
    assert views[0].pred_label.shape == (4, 5)
    assert torch.equal(views[0].pred_label, views[1].pred_label)
    torch.testing.assert_close(views[0].pred_rgb, views[1].pred_rgb, rtol=0, atol=0)
