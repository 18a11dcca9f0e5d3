"""``sray finetune-fleet --clip-frames N``: one scene's finetune (no Ray) renders a fly-through with the shared
model before its first step and with the finetuned model after, logged to the pair's run."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import torch
from fleet_fixtures import one_thread, tiny_checkpoint, tiny_fleet_config, tiny_segmenter  # noqa: F401
from train_fixtures import tiny_shards  # noqa: F401

from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.finetune.scene_artifacts import checkpoint_sha256
from sray.platform.finetune.scene_finetune import SceneTask, finetune_scene
from sray.platform.render.flythrough import Flythrough
from sray.platform.render.plan import plan_flythrough

pytestmark = pytest.mark.usefixtures("one_thread")
SCENE = "synth_test_000"
FRAMES = 2


class RecordingLogger:
    """Stands in for a run's logger: keeps the artifacts logged (path, artifact folder)."""

    def __init__(self) -> None:
        self.artifacts: list[tuple[Path, str | None]] = []

    def log_params(self, config: Any) -> None:
        """Ignored."""

    def log_metrics(self, metrics: dict[str, Any], step: int) -> None:
        """Ignored."""

    def log_artifact(self, path: Path, artifact_path: str | None = None) -> None:
        """Recorded."""
        self.artifacts.append((Path(path), artifact_path))


def _task(checkpoint: Path, shards: Path, out: Path, method: str, segmenter: Path | None = None) -> SceneTask:
    config = tiny_fleet_config(max_steps=2, eval_every=2, lr=0.05)
    config.transfer.segmenter = str(segmenter or "")
    return SceneTask(scene=SCENE, method=method, checkpoint=str(checkpoint), base_sha256=checkpoint_sha256(checkpoint),
                     shards=str(shards), out_dir=str(out), run=None, attempt=1, config=config, clip_frames=FRAMES)


def _first_frame(path: Path) -> np.ndarray:
    """The first frame of a video, RGB."""
    capture = cv2.VideoCapture(str(path))
    ok, frame = capture.read()
    capture.release()
    assert ok, path
    return frame[..., ::-1].astype(np.float64)


def test_clips_show_the_model_before_and_after_finetuning(tiny_shards, tiny_checkpoint, tmp_path):
    logger = RecordingLogger()
    outcome = finetune_scene(_task(tiny_checkpoint, tiny_shards, tmp_path, "sray"), logger)
    cfg = tiny_fleet_config().finetune
    plan = plan_flythrough(tiny_shards, SCENE, n_frames=FRAMES)
    models = {"before": model_from_checkpoint(tiny_checkpoint)[0], "after": outcome.model}
    for stage, net in models.items():
        folder = tmp_path / f"flythrough_{stage}"
        assert {p.name for p in folder.iterdir()} == {"flythrough.webm", "flythrough.mp4", "flythrough.gif",
                                                      "frames.json", "protocol.txt"}
        assert {(p.name, a) for p, a in logger.artifacts if a == f"flythrough/{stage}"} == {
            (p.name, f"flythrough/{stage}") for p in folder.iterdir()}
        expected, _ = Flythrough(net, plan, cfg.held_out.n_source, cfg.held_out.fast()).picture(
            0, torch.device("cpu"), f"{stage} finetuning")
        mse = np.mean((_first_frame(folder / "flythrough.webm") - expected) ** 2)
        assert 10 * np.log10(255.0**2 / max(mse, 1e-12)) >= 30.0, stage


@pytest.mark.parametrize("method", ["semantic-nerf", "2d-transfer"])
def test_methods_without_an_sray_network_get_no_clip(method, tiny_shards, tiny_checkpoint, tiny_segmenter, tmp_path):
    """Semantic-NeRF (no sources) and 2d-transfer (sources, but a 2D segmenter) render no fly-through."""
    logger = RecordingLogger()
    finetune_scene(_task(tiny_checkpoint, tiny_shards, tmp_path, method, tiny_segmenter), logger)
    assert not list(tmp_path.glob("flythrough_*")) and not any(a and "flythrough" in a for _, a in logger.artifacts)
