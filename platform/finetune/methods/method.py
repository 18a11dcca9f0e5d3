"""What a per-scene method is: the :class:`Method` record the registry holds, and what its builder
gets (:class:`SceneContext`) and returns (:class:`SceneSetup`).

A fleet task (:mod:`sray.platform.finetune.scene_finetune`) builds the method's learner for one
scene, trains it on the scene's rays (:meth:`Learner.loss` and its shared training step), scores it
on the held-out views with :meth:`Learner.renderer`, and stores the best state with
:meth:`Learner.save` as ``Method.artifact_file``; :meth:`Method.load_artifact` reads it back. Charts
draw the method with its :class:`ChartStyle`. ``sray eval`` scores a method's pretrained model, with no per-scene
step, through its ``eval_model`` builder (given an :class:`EvalRequest`). This module imports nothing heavy (no
torch): the CLI builds its ``--methods`` choices from the registry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from sray.platform.viz.chart_style import ChartStyle

if TYPE_CHECKING:
    import torch
    from torch import nn

    from sray.model.fast_render import FastRender
    from sray.platform.config.fleet_config import FleetConfig
    from sray.platform.eval.eval_model import EvalModel
    from sray.platform.config.train_config import TrainConfig
    from sray.platform.finetune.learners import Learner


@dataclass(frozen=True)
class SceneContext:
    """Everything a method's builder may use for one scene of a fleet."""

    scene: str
    """Scene name in the shard manifest."""
    shards: Path
    """Shard folder (``manifest.json``)."""
    base: nn.Module
    """The shared S-Ray model of the fleet's checkpoint (on CPU, freshly loaded for this task)."""
    base_sha256: str
    """sha256 of that checkpoint's ``state.pt`` (what an artifact built on it records)."""
    train_cfg: TrainConfig
    """The checkpoint's training config (rays per batch, samples per ray, ... that methods inherit)."""
    cfg: FleetConfig
    """The fleet's configuration (budgets, learning rates, method settings)."""
    n_classes: int
    """Classes of the label space (the checkpoint's and the scene's)."""
    ignore_id: int
    """Label id of unlabelled pixels."""
    stored_neighbours: int
    """Ranked source-view neighbours the shards store per view."""
    device: torch.device
    """Device the task trains on."""


@dataclass(frozen=True)
class SceneSetup:
    """What a method's builder returns: the learner and how training samples are drawn for it."""

    learner: Learner
    """The method's per-scene learner (loss, update step, renderer, snapshot/restore, save)."""
    n_source: int
    """Source views per training sample (1 for methods that use none: only the query's rays count)."""
    top_k: int
    """Training sources are drawn from this many top-ranked neighbours of the query."""
    source_labels: bool = False
    """Training samples also carry their source views' labels (a method that trains on whole source images)."""


@dataclass(frozen=True)
class EvalRequest:
    """What ``sray eval`` hands a method's ``eval_model`` builder (each method reads what it needs)."""

    checkpoint: Path | None
    """``--checkpoint``: an S-Ray training checkpoint folder."""
    segmenter: Path | None
    """``--segmenter``: a 2D segmenter folder (``sray bench segmenter``)."""
    device: str | None
    """``--device`` (None: CUDA if available, else the CPU)."""
    fast: FastRender | None
    """``--render fast``'s settings (None: the full render); read only by a method whose ``eval_reads`` names it."""
    inputs: str = ""
    """Source-view inputs to render with (``rgbd``: an RGB checkpoint given the source depth, docs/model.md "RGB-D
    mode"; empty: the checkpoint's own ``model.inputs``); read only by a method whose ``eval_reads`` names it."""


@dataclass(frozen=True)
class Method:
    """One per-scene method a fleet can run, by name."""

    name: str
    """Registry name (``--methods``, ``result.json``'s ``method``, the result folder's name)."""
    summary: str
    """What the method does, in a few words (CLI help)."""
    build: Callable[[SceneContext], SceneSetup]
    """Builds the method's learner for one scene (imports its heavy modules on use)."""
    artifact_file: str
    """File name of the scene artifact inside ``<fleet>/scenes/<scene>/<method>/``."""
    load: Callable[[Path, Path], nn.Module]
    """``load(artifact file, shared checkpoint folder)``: the scene's model as stored, in eval mode."""
    style: ChartStyle
    """How charts draw its curves and points."""
    uses_sources: bool
    """Held-out views are rendered from the shards' fixed source views (else from none: a per-scene model)."""
    zero_shot: ChartStyle | None = None
    """Set when the step-0 score is a zero-shot model (no per-scene step): charts draw it as its own line."""
    eval_model: Callable[[EvalRequest], EvalModel] | None = None
    """Builds its pretrained model for ``sray eval`` (ValueError naming the missing flag); None: it has none (it
    trains per scene)."""
    eval_reads: tuple[str, ...] = ()
    """The :class:`EvalRequest` fields its ``eval_model`` reads besides ``device`` (``checkpoint``, ``segmenter``,
    ``fast``, ``inputs``): a command refuses the flags that set any other (``sray eval --method 2d-transfer --render
    fast``)."""
    inputs: str = ""
    """Source-view inputs its held-out protocol names (``rgb`` or ``rgbd``); empty: the shared checkpoint's
    ``model.inputs`` (S-Ray reads what its checkpoint reads)."""
    given_depth_of: str = ""
    """Set on a depth twin: the registered method it is, given the source views' depth (``sray-rgbd``: ``sray``);
    the registry stands it beside every method that reads the source depth (``with_depth_twins``)."""
    checked_config: Callable[[FleetConfig], FleetConfig] | None = None
    """Checks a fleet's config before any task starts and returns it as the tasks get it (e.g. a path made
    absolute); ValueError or FileNotFoundError naming the field and the fix. None: nothing to check."""
    clips: bool = False
    """Its learner's network is an S-Ray model that renders fly-throughs (``--clip-frames``)."""

    def load_artifact(self, result_dir: Path, base_checkpoint: Path) -> nn.Module:
        """The model stored in ``<result_dir>/<artifact_file>`` (``result_dir``: a pair's result folder)."""
        return self.load(Path(result_dir) / self.artifact_file, Path(base_checkpoint))
