"""Held-out renders (validation, the fleet, ``sray eval``, ``sray render``): one setting type, the fast mode by
default, the full render one setting away, bad values refused by name (as a config field or as a flag), and the
protocol descriptor saying which render made the scores."""

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
from sray.jobs.cli import build_parser
from sray.jobs.render_flags import held_out_from_args
from sray.platform.config.held_out_render import HeldOutRender
from sray.platform.config.train_config import apply_override
from sray.platform.eval.view_scoring import predict_view, sray_renderer
from sray.platform.finetune.learners import SRayLearner
from sray.platform.train.validation import validation_protocol


def test_fast_renders_its_own_pixel_stride_and_bad_values_name_the_setting() -> None:
    assert HeldOutRender(fast_stride=1, fast_confidence=0.8).fast() == FastRender(pixel_stride=1, confidence=0.8)
    assert HeldOutRender().fast() == FastRender() and HeldOutRender(render="full").fast() is None
    with pytest.raises(ValueError, match=r"f\.render is 'quick'; use one of \('fast', 'full'\)"):
        HeldOutRender(render="quick").check(lambda field: f"f.{field}")
    with pytest.raises(ValueError, match=r"f\.fast_confidence is 0\.0; it must be > 0"):
        HeldOutRender(fast_confidence=0.0).check(lambda field: f"f.{field}")
    assert HeldOutRender(n_source=0).sources(4) == 4 and HeldOutRender(n_source=3).sources(4) == 3


def test_train_and_fleet_configs_refuse_a_bad_render_and_keep_their_value(tiny_shards: Path, tmp_path: Path) -> None:
    """``--set data.held_out.<field>`` goes through the one override mechanism; validation's protocol follows."""
    cfg = tiny_config(tiny_shards, tmp_path)
    with pytest.raises(ValueError, match="data.held_out.render is 'quick'"):
        apply_override(cfg, "data.held_out.render=quick")
    assert cfg.data.held_out.render == "fast"
    apply_override(cfg, "data.held_out.render=full")
    assert validation_protocol(cfg).render == "full"
    apply_override(cfg, "data.held_out.fast_confidence=0.7")
    apply_override(cfg, "data.held_out.render=fast")
    apply_override(cfg, "data.held_out.stride=4")
    protocol = validation_protocol(cfg)
    assert protocol.render == FastRender(1, 0.7).describe() and protocol.stride == 4
    assert protocol.n_source == cfg.model.n_source  # n_source 0: the model's own
    with pytest.raises(ValueError, match="data.held_out.stride is 0"):
        apply_override(cfg, "data.held_out.stride=0")
    fleet = tiny_fleet_config()
    fleet.finetune.held_out.render = "nope"
    with pytest.raises(ValueError, match="finetune.held_out.render is 'nope'"):
        check_fleet_config(fleet)


@pytest.mark.parametrize("command", ["eval", "render"])
def test_eval_and_render_flags_parse_into_the_one_setting_type(command: str) -> None:
    """The same flags and defaults in both commands; a bad value is refused by its flag."""
    base = {"eval": ["eval", "--data", "d", "--checkpoint", "c"],
            "render": ["render", "--data", "d", "--checkpoint", "c", "--scene", "s"]}[command]
    assert held_out_from_args(build_parser().parse_args(base)) == HeldOutRender()
    args = build_parser().parse_args([*base, "--render", "full", "--n-source", "4", "--fast-stride", "2",
                                      "--fast-confidence", "0.5"])
    assert held_out_from_args(args) == HeldOutRender(n_source=4, render="full", fast_stride=2, fast_confidence=0.5)
    with pytest.raises(ValueError, match="--fast-stride is 0"):
        held_out_from_args(build_parser().parse_args([*base, "--fast-stride", "0"]))
    with pytest.raises(ValueError, match="--n-source is 0"):
        held_out_from_args(build_parser().parse_args([*base, "--n-source", "0"]))


@pytest.mark.parametrize("render", ["fast", "full"])
def test_the_finetune_learners_held_out_renderer_is_the_chosen_render(tiny_checkpoint: Path, tiny_shards: Path,
                                                                      render: str) -> None:
    """With the encoder frozen the learner reuses encoded sources; its views equal a fresh ``sray_renderer``
    of the same mode, and the fast views differ from the full ones (the render really changed). The fast
    mode's threshold is one every coarse ray reaches: with no fine pass its views are the coarse pass's,
    while a fine pass on every ray would equal the full render (both evaluate the resampled depths only)."""
    net, _ = model_from_checkpoint(tiny_checkpoint)
    fast = HeldOutRender(render=render, fast_stride=1, fast_confidence=1e-3).fast()
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
