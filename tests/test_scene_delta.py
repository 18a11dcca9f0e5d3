"""Scene artifacts: shared model + artifact = the finetuned model, bit for bit; small; bound to their base."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from fleet_fixtures import one_thread, tiny_checkpoint, tiny_fleet_config, write_tiny_checkpoint  # noqa: F401
from safetensors import safe_open
from train_fixtures import tiny_shards  # noqa: F401

from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.model.semantic_nerf import SemanticNeRF, SemanticNeRFConfig
from sray.platform.checkpoints.folders import load_checkpoint
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.config.fleet_config import DEFAULT_ADAPT
from sray.platform.finetune.learners import SRayLearner
from sray.platform.finetune.methods.registry import get_method
from sray.platform.finetune.scene_artifacts import (
    adapted_keys,
    checkpoint_sha256,
    load_scene_model,
    load_semantic_nerf,
    save_sray_delta,
    save_whole,
)
from sray.platform.finetune.scene_finetune import SceneOutcome, SceneTask, evaluate, finetune_scene

SCENE = "synth_test_000"
pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def finetuned(one_thread: None, tiny_shards: Path, tiny_checkpoint: Path,
              tmp_path_factory: pytest.TempPathFactory) -> tuple[SceneOutcome, Path]:
    """A 6-step S-Ray finetune of the tiny test scene (default adapted modules) and its artifact."""
    out = tmp_path_factory.mktemp("delta")
    job = SceneTask(scene=SCENE, method="sray", checkpoint=str(tiny_checkpoint),
                   base_sha256=checkpoint_sha256(tiny_checkpoint), shards=str(tiny_shards), out_dir=str(out), run=None,
                   attempt=1, config=tiny_fleet_config(patience=5))
    return finetune_scene(job), out / get_method("sray").artifact_file


def _render(net: torch.nn.Module, sample: EvalSample) -> dict:
    with torch.no_grad():
        src = net.encode(sample.sources.rgb, sample.sources.K, sample.sources.c2w)
        h, w = sample.query_label.shape
        return net.render_image(src, sample.query.K, sample.query.c2w, (h, w), sample.near, sample.far)


def test_artifact_reproduces_the_finetuned_model_exactly(finetuned, tiny_shards, tiny_checkpoint):
    outcome, artifact = finetuned
    loaded = load_scene_model(tiny_checkpoint, artifact)
    base, _ = model_from_checkpoint(tiny_checkpoint)
    sample = next(make_eval_samples(tiny_shards, SCENE, "test", n_source=3))
    tuned_out, loaded_out, base_out = _render(outcome.model, sample), _render(loaded, sample), _render(base, sample)
    for p in ("coarse", "fine"):
        for k in ("logits", "rgb", "depth"):
            assert torch.equal(tuned_out[p][k], loaded_out[p][k]), (p, k)
    assert not torch.equal(tuned_out["fine"]["logits"], base_out["fine"]["logits"])  # the finetune changed it
    # The artifact holds the best evaluated state: re-scoring the reloaded model gives miou_after exactly.
    samples = list(make_eval_samples(tiny_shards, SCENE, "test", n_source=3))
    ft = tiny_fleet_config().finetune  # the same held-out render as the finetune's (finetune.held_out)
    learner = SRayLearner(loaded, "-", DEFAULT_ADAPT, 0.0, 0.0, "no", torch.device("cpu"), 20, ft.held_out.fast())
    scores = evaluate(learner, samples, tiny_fleet_config(), n_classes=20, ignore_id=255)
    assert scores["miou"] == outcome.result["miou_after"] and scores["psnr"] == outcome.result["psnr_after"]


def test_artifact_holds_only_the_adapted_tensors_and_is_small(finetuned, tiny_checkpoint):
    outcome, artifact = finetuned
    base, _ = model_from_checkpoint(tiny_checkpoint)
    with safe_open(str(artifact), framework="pt") as f:
        keys, meta = set(f.keys()), f.metadata()
    assert keys == set(adapted_keys(base, DEFAULT_ADAPT))
    assert meta["base_sha256"] == checkpoint_sha256(tiny_checkpoint)
    full = sum(t.numel() * t.element_size() for t in load_checkpoint(tiny_checkpoint)["model"].values())
    assert outcome.result["full_checkpoint_bytes"] == full
    stored = sum(t.numel() * t.element_size() for k, t in base.state_dict().items() if k in keys)
    assert outcome.result["artifact_bytes"] == artifact.stat().st_size
    assert stored < outcome.result["artifact_bytes"] < stored + 16 * 1024  # the tensors + a JSON header
    assert outcome.result["artifact_bytes"] < 0.05 * full


def test_artifact_of_another_base_is_refused(finetuned, tiny_shards, tmp_path):
    _, artifact = finetuned
    other = write_tiny_checkpoint(tiny_shards, tmp_path, seed=1)
    with pytest.raises(ValueError, match="base checksum mismatch"):
        load_scene_model(other, artifact)


def test_artifact_of_another_configuration_is_refused(tiny_checkpoint, tmp_path):
    bad = tmp_path / "bad.safetensors"
    save_sray_delta(bad, {"fine.classifier.0.weight": torch.zeros(3, 3)}, checkpoint_sha256(tiny_checkpoint),
                    ["fine.classifier"], SCENE)
    with pytest.raises(ValueError, match="has shape"):
        load_scene_model(tiny_checkpoint, bad)
    base, _ = model_from_checkpoint(tiny_checkpoint)
    with pytest.raises(ValueError, match="names no part"):
        adapted_keys(base, ["fine.nonexistent"])


def test_semantic_nerf_artifact_round_trip(tmp_path):
    torch.manual_seed(0)
    cfg = SemanticNeRFConfig(n_classes=5, depth=3, width=16, skip_layer=2, n_coarse=6, n_fine=6,
                             scene_center=(0.5, -0.2, 1.0), scene_scale=2.5)
    net = SemanticNeRF(cfg).eval()
    path = tmp_path / "nerf.safetensors"
    save_whole(path, net, "s", "semantic-nerf")
    loaded = load_semantic_nerf(path)
    assert loaded.cfg == cfg
    origins, dirs = torch.randn(32, 3), torch.randn(32, 3)
    a = net.render_rays(origins, dirs, 0.5, 4.0, stratified=False)
    b = loaded.render_rays(origins, dirs, 0.5, 4.0, stratified=False)
    for p in ("coarse", "fine"):
        assert torch.equal(a[p]["logits"], b[p]["logits"]) and torch.equal(a[p]["rgb"], b[p]["rgb"])
    with pytest.raises(ValueError, match="not an S-Ray scene artifact"):
        load_scene_model(Path("unused"), path)
