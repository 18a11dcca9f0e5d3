"""A per-scene method: the :class:`Method` record, what its builder gets and returns (imports nothing heavy)."""

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
    shards: Path
    base: nn.Module
    """The shared S-Ray model of the fleet's checkpoint (on CPU, freshly loaded for this task)."""
    base_sha256: str
    """sha256 of that checkpoint's ``state.pt``."""
    train_cfg: TrainConfig
    """The checkpoint's training config (the settings methods inherit)."""
    cfg: FleetConfig
    n_classes: int
    ignore_id: int
    stored_neighbours: int
    """Ranked source-view neighbours the shards store per view."""
    device: torch.device


@dataclass(frozen=True)
class SceneSetup:
    """What a method's builder returns: the learner and how training samples are drawn for it."""

    learner: Learner
    n_source: int
    """Source views per training sample (1 for methods that use none)."""
    top_k: int
    """Training sources are drawn from this many top-ranked neighbours of the query."""
    source_labels: bool = False
    """Training samples also carry their source views' labels."""


@dataclass(frozen=True)
class EvalRequest:
    """What ``sray eval`` hands a method's ``eval_model`` builder (each method reads what it needs)."""

    checkpoint: Path | None
    segmenter: Path | None
    device: str | None
    """``--device`` (None: CUDA if available, else the CPU)."""
    fast: FastRender | None
    """``--render fast``'s settings (None: the full render)."""
    inputs: str = ""
    """Source-view inputs to render with (``rgbd``: docs/model.md "RGB-D mode"; empty: the checkpoint's own)."""


@dataclass(frozen=True)
class Method:
    """One per-scene method a fleet can run, by name."""

    name: str
    """Registry name (``--methods``, ``result.json``'s ``method``, the result folder's name)."""
    summary: str
    """CLI help."""
    build: Callable[[SceneContext], SceneSetup]
    """Builds the method's learner for one scene (imports its heavy modules on use)."""
    artifact_file: str
    """File name of the scene artifact inside ``<fleet>/scenes/<scene>/<method>/``."""
    load: Callable[[Path, Path], nn.Module]
    """``load(artifact file, shared checkpoint folder)``: the scene's model as stored, in eval mode."""
    style: ChartStyle
    uses_sources: bool
    """Held-out views are rendered from the shards' fixed source views (else from none: a per-scene model)."""
    zero_shot: ChartStyle | None = None
    """Set when the step-0 score is a zero-shot model: charts draw it as its own line."""
    eval_model: Callable[[EvalRequest], EvalModel] | None = None
    """Builds its pretrained model for ``sray eval`` (None: it trains per scene only)."""
    eval_reads: tuple[str, ...] = ()
    """The :class:`EvalRequest` fields ``eval_model`` reads besides ``device``: commands refuse flags setting others."""
    inputs: str = ""
    """Source-view inputs its held-out protocol names; empty: the shared checkpoint's ``model.inputs``."""
    given_depth_of: str = ""
    """Set on a depth twin: the method it is, given the source depth (``sray-rgbd``: ``sray``)."""
    checked_config: Callable[[FleetConfig], FleetConfig] | None = None
    """Checks a fleet's config before any task starts and returns it as the tasks get it."""
    clips: bool = False
    """Its network is an S-Ray model that renders fly-throughs (``--clip-frames``)."""

    def load_artifact(self, result_dir: Path, base_checkpoint: Path) -> nn.Module:
        """The model stored in ``<result_dir>/<artifact_file>`` (``result_dir``: a pair's result folder)."""
        return self.load(Path(result_dir) / self.artifact_file, Path(base_checkpoint))
