"""``sray lab recipe-step``: the phase clock's attribution, the source-count normalisation, the lever arguments,
and end-to-end runs on tiny shards whose levers reach the measured step, of a ray step and of a 2D step."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import pytest
import scene_fixtures
import torch
from torch import nn

from sray.data_tools.shards.writer import write_shards
from sray.lab.recipe.step import (
    PHASES,
    PhaseClock,
    StepCosts,
    expected_sources,
    parse_levers,
    run_recipe_step,
)
from sray.platform.config.recipes import get_recipe


def _spin(seconds: float) -> None:
    """Burn ``seconds`` of this process's CPU time."""
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass


class _Spinner(nn.Module):
    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds, self.w = seconds, nn.Parameter(torch.ones(1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _spin(self.seconds)
        return x * self.w


class _Net(nn.Module):
    def __init__(self) -> None:
        super().__init__()
        self.encoder, self.coarse, self.other = _Spinner(0.06), _Spinner(0.03), _Spinner(0.04)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.other(self.coarse(self.encoder(x)))


def test_phase_clock_counts_each_hooked_module_and_the_optimizer_and_stops_when_closed() -> None:
    net = _Net()
    opt = torch.optim.SGD(net.parameters(), lr=0.1)
    clock = PhaseClock(net, opt)
    net(torch.ones(1)).sum().backward()
    forward = clock.take()
    assert set(forward) == {"encoder", "coarse field"}  # `other` is not a phase, it stays in "forward rest"
    assert forward["encoder"] == pytest.approx(0.06, abs=0.01)
    assert forward["coarse field"] == pytest.approx(0.03, abs=0.01)
    opt.step()
    assert set(clock.take()) == {"optimizer"}
    clock.close()
    net(torch.ones(1))
    opt.step()
    assert clock.take() == {}


def test_step_cost_at_a_source_count_reads_the_least_squares_line() -> None:
    costs = StepCosts(per_step=[(2, 0.30), (4, 0.50), (8, 0.90), (6, 0.70)])  # 0.1 s + 0.1 s per source, exactly
    assert costs.total_ms_at(5.0) == pytest.approx(600.0)
    flat = StepCosts(per_step=[(8, 0.4), (8, 0.6)])
    assert flat.total_ms_at(5.0) == pytest.approx(500.0)  # one count only: the plain mean


def test_expected_sources_follow_the_recipes_draw() -> None:
    cfg = get_recipe("synth-cpu-hour")
    cfg.model.n_source, cfg.data.aug = 8, dataclasses.replace(cfg.data.aug, min_source=2)
    assert expected_sources(cfg) == 5.0
    cfg.data.aug = dataclasses.replace(cfg.data.aug, min_source=0)
    assert expected_sources(cfg) == 8.0


@pytest.mark.parametrize("spec", [["rays"], ["rays", "128"], ["data.rays_per_batch=128"], ["recipe", "a.b=1"]])
def test_a_malformed_or_taken_lever_name_is_refused(spec: list[str]) -> None:
    with pytest.raises(ValueError, match="--lever"):
        parse_levers([spec])


def test_recipe_step_measures_every_variant_and_its_overrides_reach_the_step(tmp_path: Path) -> None:
    scenes = scene_fixtures.write_dataset(tmp_path / "scenes", [("a", 14, "train"), ("b", 14, "train")],
                                         height=48, width=64)
    shards = tmp_path / "shards"
    write_shards(scenes, shards, views_per_shard=7, neighbours=13, progress=False)
    doc = tmp_path / "benchmarks.md"
    costs = run_recipe_step("synth-cpu-hour", shards, [["no-head", "optim.warmup_2d_steps=0", "model.lambda_src_sem=0"],
                                                       ["two-sources", "model.n_source=2", "data.aug.min_source=0"]],
                            steps=2, rounds=1, warm_up=0, doc=doc)
    assert list(costs) == ["recipe", "no-head", "two-sources"]
    for c in costs.values():
        assert c.steps == 2 and set(c.seconds) == set(PHASES)
    assert costs["recipe"].seconds["source head"] > 0 and costs["no-head"].seconds["source head"] == 0
    assert costs["two-sources"].sources == 4  # two steps of exactly two views
    assert 2 * 2 <= costs["recipe"].sources <= 2 * 8  # the recipe draws 2-8 per sample
    text = doc.read_text()
    assert "Ray step of synth-cpu-hour, by phase" in text
    assert "`no-head`: `optim.warmup_2d_steps=0` `model.lambda_src_sem=0`" in text
    flat = run_recipe_step("synth-cpu-hour", shards, [], steps=1, rounds=1, warm_up=0, doc=doc, phase="2d")
    assert flat["recipe"].seconds["encoder"] > 0 and flat["recipe"].seconds["source head"] > 0
    assert flat["recipe"].seconds["coarse field"] == flat["recipe"].seconds["fine field"] == 0  # nothing rendered
    text = doc.read_text()
    assert "2D warm-up step of synth-cpu-hour, by phase" in text and "Ray step of synth-cpu-hour, by phase" in text
    with pytest.raises(ValueError, match="--phase"):
        run_recipe_step("synth-cpu-hour", shards, [], steps=1, rounds=1, warm_up=0, doc=doc, phase="3d")
