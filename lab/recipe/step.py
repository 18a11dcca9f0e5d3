"""``sray lab recipe-step``: where one training step of a recipe spends its CPU, measured on real shards, and what
each step-cost lever (a set of ``--set`` overrides) saves; the step is a ray step (``--phase rays``) or a step of the
2D warm-up (``--phase 2d``: the encoder and its source-view head on the source labels, nothing rendered).

One process plays one training rank of the recipe: its loader runs in this process (so reading, decoding and
augmenting a sample are counted on the same clock), torch gets the rank's ``run.cpus_per_worker`` threads (what a
Ray worker of the recipe is given), and each step is the worker's own: ``RayBatchLoss`` forward with rendering on,
then ``TrainStep`` (backward, clipping, Adam); a 2D step runs the same forward with rendering off. The CPU seconds
of each phase are read with ``time.process_time`` around the step's parts and from forward hooks on the network's
modules (encoder, source-view head, coarse and fine fields) and step hooks on the optimizer. What one rank of a
multi-rank job adds (the gradient all-reduce) is not in these figures.

Variants (the recipe and each lever) run in the same process, alternating round by round, each with its own
model and loader built from the same seed (a lever that changes what the loader draws, such as the rays per
sample, also changes its later draws, the source counts among them; the table compares the variants at their
expected source count); a load change on the machine hits all of them alike.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from sray.platform.common.bench_doc import Bench, record
from sray.platform.common.doc_blocks import markdown_table
from sray.platform.common.model_input import ray_batch
from sray.platform.config.recipes import get_recipe
from sray.platform.config.train_config import TrainConfig, apply_override
from sray.platform.train.job_loader import job_loader
from sray.platform.train.state import build_training
from sray.platform.train.step import TrainStep, step_seed

PHASES = ("load", "encoder", "source head", "coarse field", "fine field", "forward rest", "backward", "optimizer")
"""The parts of a ray step, in order: the sample's loading (read, decode, augment), the forward of the encoder, of
the source-view head and of each field (every call of the module, hooks), the rest of the forward (rays, sampling,
reprojection outside the fields, compositing, losses), the backward with gradient clipping, and the Adam update."""

_MODULE_PHASES = {"encoder": "encoder", "src_head": "source head", "coarse": "coarse field", "fine": "fine field"}


@dataclasses.dataclass
class StepCosts:
    """CPU seconds per phase summed over the measured steps of one variant, and what those steps held."""

    seconds: dict[str, float] = dataclasses.field(default_factory=lambda: dict.fromkeys(PHASES, 0.0))
    source_pixels: int = 0
    """Source-view pixels summed over the steps."""
    per_step: list[tuple[int, float]] = dataclasses.field(default_factory=list)
    """(source views, CPU seconds) of each measured step (the recipe's loader may draw a different count per
    sample)."""

    @property
    def steps(self) -> int:
        """Measured steps."""
        return len(self.per_step)

    @property
    def sources(self) -> int:
        """Source views summed over the measured steps."""
        return sum(m for m, _ in self.per_step)

    def per_step_ms(self) -> dict[str, float]:
        """Mean CPU milliseconds per step of each phase."""
        return {k: 1e3 * v / max(self.steps, 1) for k, v in self.seconds.items()}

    def total_ms(self) -> float:
        """Mean CPU milliseconds of a whole step (the phases' sum)."""
        return sum(self.per_step_ms().values())

    def total_ms_at(self, sources: float) -> float:
        """CPU milliseconds of a whole step with ``sources`` source views: the least-squares line of the steps'
        seconds against their source count, read at ``sources`` (the plain mean when every step had one count).
        Variants whose loaders drew different source counts are compared at their draws' expected count."""
        counts = np.array([m for m, _ in self.per_step], dtype=float)
        seconds = np.array([t for _, t in self.per_step])
        if len(np.unique(counts)) < 2:
            return 1e3 * float(seconds.mean())
        slope, intercept = np.polyfit(counts, seconds, 1)
        return 1e3 * float(intercept + slope * sources)


class PhaseClock:
    """The CPU time of a network's module forwards and of an optimizer's steps, by phase.

    Hooks the network's direct children named in ``_MODULE_PHASES`` (none of them calls another, so no time is
    counted twice) and the optimizer's ``step``. Remove the hooks with :meth:`close`."""

    def __init__(self, net: nn.Module, optimizer: torch.optim.Optimizer) -> None:
        self._started: dict[str, float] = {}
        self._handles: list[Any] = []
        for attr, phase in _MODULE_PHASES.items():
            module = getattr(net, attr, None)
            if isinstance(module, nn.Module):
                self._handles.append(module.register_forward_pre_hook(self._start(phase)))
                self._handles.append(module.register_forward_hook(self._stop(phase)))
        self._handles.append(optimizer.register_step_pre_hook(self._start("optimizer")))
        self._handles.append(optimizer.register_step_post_hook(self._stop("optimizer")))
        self.hooked: dict[str, float] = {}
        """Seconds per hooked phase since the last :meth:`take`."""

    def _start(self, phase: str) -> Callable[..., None]:
        def hook(*_: Any) -> None:
            self._started[phase] = time.process_time()
        return hook

    def _stop(self, phase: str) -> Callable[..., None]:
        def hook(*_: Any) -> None:
            self.hooked[phase] = self.hooked.get(phase, 0.0) + time.process_time() - self._started.pop(phase)
        return hook

    def take(self) -> dict[str, float]:
        """The hooked seconds gathered since the last call (and start afresh)."""
        taken, self.hooked = self.hooked, {}
        return taken

    def close(self) -> None:
        """Remove every hook."""
        for handle in self._handles:
            handle.remove()


class VariantRunner:
    """One variant's rank: its model, optimizer, step and loader stream, and the costs of its measured steps."""

    def __init__(self, cfg: TrainConfig, epoch_steps: int, render: bool = True) -> None:
        self.cfg, self.render = cfg, render
        model, optimizer, _ = build_training(cfg)
        self.model, self.device = model, torch.device("cpu")
        self.train_step = TrainStep(list(model.parameters()), optimizer, cfg.optim.grad_clip, cfg.run.precision,
                                    self.device, cfg.optim.max_nonfinite_in_row)
        self.stream: Iterator = iter(job_loader(cfg, 0, 1, epoch_steps))
        self.costs = StepCosts()
        self.clock = PhaseClock(model.net, optimizer)
        self.step = 0

    def run(self, steps: int, measure: bool) -> None:
        """Run ``steps`` steps (ray steps, or 2D steps unless ``render``); add their phase costs when ``measure``."""
        for _ in range(steps):
            t0 = time.process_time()
            sample = next(self.stream)
            t1 = time.process_time()
            self.clock.take()
            torch.manual_seed(step_seed(self.cfg.run.seed, 0, self.step))
            self.model.train()
            with self.train_step.autocast():
                loss, _ = self.model(ray_batch(sample), sample.target_label, sample.target_rgb, render=self.render)
            t2 = time.process_time()
            forward = self.clock.take()
            self.train_step(loss)
            t3 = time.process_time()
            after = self.clock.take()
            self.step += 1
            if not measure:
                continue
            c = self.costs
            c.seconds["load"] += t1 - t0
            for phase, s in forward.items():
                c.seconds[phase] += s
            c.seconds["forward rest"] += (t2 - t1) - sum(forward.values())
            c.seconds["optimizer"] += after.get("optimizer", 0.0)
            c.seconds["backward"] += (t3 - t2) - after.get("optimizer", 0.0)
            c.source_pixels += int(sample.sources.rgb[:, 0].numel())
            c.per_step.append((int(sample.sources.rgb.shape[0]), t3 - t0))

    def close(self) -> None:
        """Remove the phase hooks."""
        self.clock.close()


def variant_config(recipe: TrainConfig, shards: Path, assignments: list[str]) -> TrainConfig:
    """The recipe on ``shards`` with ``assignments`` (``section.field=value``) applied, its loader in this process."""
    cfg = copy.deepcopy(recipe)
    apply_override(cfg, f"data.shards={shards}")
    for assignment in assignments:
        apply_override(cfg, assignment)
    apply_override(cfg, "data.loader_workers=0")
    return cfg


def measure_recipe_step(recipe: TrainConfig, shards: Path, levers: dict[str, list[str]], steps: int = 20,
                        rounds: int = 3, warm_up: int = 3, phase: str = "rays") -> dict[str, StepCosts]:
    """Phase costs of the recipe's step of ``phase`` (a ``STEP_TITLES`` key; variant ``"recipe"``) and of each lever
    (name -> overrides) on ``shards``: ``warm_up`` unmeasured steps per variant, then ``rounds`` rounds of ``steps``
    steps, the variants alternating."""
    torch.set_num_threads(max(1, int(recipe.run.cpus_per_worker)))
    configs = {"recipe": variant_config(recipe, shards, [])}
    configs |= {name: variant_config(recipe, shards, sets) for name, sets in levers.items()}
    epoch_steps = warm_up + steps * rounds
    runners = {name: VariantRunner(cfg, epoch_steps, render=phase == "rays") for name, cfg in configs.items()}
    try:
        for name, runner in runners.items():
            runner.run(warm_up, measure=False)
        for r in range(rounds):
            for name, runner in runners.items():
                runner.run(steps, measure=True)
                print(f"[bench] recipe step {name}, round {r + 1}/{rounds}: {runner.costs.total_ms():.0f} CPU ms per "
                      "step so far", flush=True)
    finally:
        for runner in runners.values():
            runner.close()
    return {name: runner.costs for name, runner in runners.items()}


RECIPE_STEP = Bench("recipe-step", "Recipe step")
"""The section of ``sray lab recipe-step``'s tables: a recipe's step by phase, and its step-cost levers."""

STEP_TITLES = {"rays": "Ray step of {recipe}, by phase", "2d": "2D warm-up step of {recipe}, by phase"}
"""The step kinds ``--phase`` measures, and the title of each one's table (one table per recipe and kind)."""


def expected_sources(cfg: TrainConfig) -> float:
    """The mean source-view count of ``cfg``'s training samples: uniform in [``aug.min_source``, ``n_source``], or
    always ``n_source`` without that augmentation."""
    n, low = cfg.model.n_source, cfg.data.aug.min_source
    return (min(low, n) + n) / 2 if low > 0 else float(n)


def recipe_step_table(costs: dict[str, StepCosts], sources: dict[str, float], phase: str = "rays") -> str:
    """Markdown table: CPU milliseconds per step of ``phase`` by part (rows) for each variant (columns), the whole
    step, the whole step at the variant's expected source count ``sources[variant]`` and its ratio to the recipe's,
    and the mean sources and source pixels per step."""
    names = list(costs)
    at = {n: costs[n].total_ms_at(sources[n]) for n in names}
    rows = [[part, *(f"{costs[n].per_step_ms()[part]:.0f}" for n in names)] for part in PHASES]
    rows.append(["whole step", *(f"{costs[n].total_ms():.0f}" for n in names)])
    rows.append(["**whole step at the expected sources**", *(f"**{at[n]:.0f}**" for n in names)])
    rows.append(["step CPU vs the recipe", *(f"{at[n] / at['recipe']:.2f}x" for n in names)])
    rows.append(["sources per step (expected)", *(f"{costs[n].sources / max(costs[n].steps, 1):.2f} "
                                                  f"({sources[n]:.1f})" for n in names)])
    rows.append(["source kpixels per step", *(f"{costs[n].source_pixels / max(costs[n].steps, 1) / 1e3:.1f}"
                                              for n in names)])
    return markdown_table([f"CPU ms per {'ray' if phase == 'rays' else '2D'} step", *names], rows)


def write_recipe_step(recipe: str, costs: dict[str, StepCosts], sources: dict[str, float],
                      levers: dict[str, list[str]], steps: int, rounds: int, doc: Path, phase: str = "rays") -> str:
    """Record the table of ``recipe``'s step of ``phase`` in ``doc``'s "Recipe step" section (the same recipe and
    phase's table replaced); returns the table."""
    table = recipe_step_table(costs, sources, phase)
    lever_lines = "; ".join(f"`{name}`: {' '.join(f'`{a}`' for a in sets)}" for name, sets in levers.items())
    notes = (f"One rank of `{recipe}` on real shards, its loader in the same process, "
             f"{steps} x {rounds} measured {'ray' if phase == 'rays' else '2D'} steps per variant after a warm-up, "
             "the variants alternating round by round from the same seed; CPU seconds from `time.process_time` "
             "(forward hooks on the modules, step hooks on Adam); the gradient all-reduce of a multi-rank job is not "
             "included. The loaders draw a source count per sample, and a lever's stream may draw other counts than "
             "the recipe's: the bold row reads each variant's least-squares line of step CPU against source count at "
             "its draw's expected count. "
             + (f"Levers: {lever_lines}." if levers else "No levers."))
    record(RECIPE_STEP, STEP_TITLES[phase].format(recipe=recipe), table, doc, notes)
    return table


def parse_levers(specs: list[list[str]]) -> dict[str, list[str]]:
    """``--lever NAME SECTION.FIELD=VALUE ...`` arguments as name -> overrides, checked for their form."""
    levers: dict[str, list[str]] = {}
    for spec in specs:
        name, sets = spec[0], spec[1:]
        if "=" in name or not sets or any("=" not in a for a in sets):
            raise ValueError(f"--lever {' '.join(spec)}: give a name, then one or more SECTION.FIELD=VALUE "
                             "overrides, e.g. --lever rays-128 data.rays_per_batch=128")
        if name in levers or name == "recipe":
            raise ValueError(f"--lever {name}: the name is taken (by another lever, or 'recipe' by the recipe itself)")
        levers[name] = sets
    return levers


def run_recipe_step(recipe: str, shards: Path, lever_specs: list[list[str]], steps: int, rounds: int, warm_up: int,
                    doc: Path, phase: str = "rays") -> dict[str, StepCosts]:
    """``sray lab recipe-step``: measure the recipe's step of ``phase`` and its levers on ``shards``, record the
    table."""
    if phase not in STEP_TITLES:
        raise ValueError(f"--phase {phase}: measure one of {', '.join(STEP_TITLES)}")
    if not (shards / "manifest.json").is_file():
        raise FileNotFoundError(
            f"{shards}: no manifest.json; pass --data a shard folder (`sray data shard` writes one)")
    if steps < 1 or rounds < 1 or warm_up < 0:
        raise ValueError(f"--steps {steps}, --rounds {rounds}, --warm-up {warm_up}: steps and rounds must be at least "
                         "1, the warm-up at least 0")
    levers = parse_levers(lever_specs)
    base = get_recipe(recipe)
    costs = measure_recipe_step(base, shards, levers, steps, rounds, warm_up, phase)
    sources = {"recipe": expected_sources(base)}
    sources |= {name: expected_sources(variant_config(base, shards, sets)) for name, sets in levers.items()}
    write_recipe_step(recipe, costs, sources, levers, steps, rounds, doc, phase)
    return costs
