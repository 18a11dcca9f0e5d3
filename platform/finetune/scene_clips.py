"""Short fly-throughs of a fleet's scene before and after its finetune (``sray finetune-fleet --clip-frames N``).

For methods that render from source views (S-Ray): the same spline path through the scene's source and
finetune cameras (``platform/render``), rendered with the fleet's held-out protocol (``finetune.held_out``'s
sources per frame and render), once with the shared model before the first step and once with
the best finetuned state. Files go to ``<pair folder>/flythrough_before/`` and ``flythrough_after/`` and into
the pair's child run under ``flythrough/before`` and ``flythrough/after``. Clip time is not training time.
"""

from __future__ import annotations

from pathlib import Path

from sray.model.semantic_ray import SRayModel
from sray.platform.config.fleet_config import FleetConfig
from sray.platform.finetune.learners import Learner
from sray.platform.render.flythrough import Flythrough
from sray.platform.render.plan import plan_flythrough
from sray.platform.render.tracked import ARTIFACT_PATH, log_flythrough
from sray.platform.tracking.tracker import RunLogger

STAGES = ("before", "after")
"""When a clip is rendered: with the shared model, then with the finetuned one."""


class SceneClips:
    """The clip plan of one scene, checked once, rendered at each stage."""

    def __init__(self, net: SRayModel, shards: Path, scene: str, frames: int, cfg: FleetConfig) -> None:
        """Plan ``frames`` frames of ``scene`` for ``net`` (ValueError before the finetune starts on bad input)."""
        ft = cfg.finetune
        self.fly = Flythrough(net, plan_flythrough(Path(shards), scene, n_frames=frames),
                              ft.held_out.sources(net.cfg.n_source), ft.held_out.fast())

    def render(self, stage: str, learner: Learner, out_dir: Path, logger: RunLogger | None) -> dict[str, str]:
        """Render the clip of ``stage`` (:data:`STAGES`) with the learner's current state, as its held-out views
        are rendered (``Learner.inference``, its autocast), under ``out_dir/flythrough_<stage>``, and log it;
        returns {name: file}."""
        with learner.inference(), learner.step.autocast():
            result = self.fly.render(Path(out_dir) / f"flythrough_{stage}", learner.device,
                                     label=f"{stage} finetuning", progress=False)
        if logger is not None:
            log_flythrough(logger, result["files"], f"{ARTIFACT_PATH}/{stage}")
        return result["files"]
