"""RGB-D mode through the data and the platform: source depth in loader samples, the query depth never
read, ``--set model.inputs``, and ``inputs: rgbd`` in every protocol descriptor (``sray eval``, validation)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: F401  (pytest fixtures, used by name)
from train_fixtures import tiny_config, tiny_shards  # noqa: F401  (pytest fixture, used by name)

from sray.data_tools.loader.augment import Augmentation, rescale_nearest
from sray.data_tools.loader.samples import ranked_candidates, train_sample
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.shards.manifest import read_manifest
from sray.model.config import SRayConfig
from sray.model.semantic_ray import SRayModel
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.config.train_config import apply_override
from sray.platform.eval.view_scoring import predict_view, sray_renderer

N_SOURCE = 3


def _test_scene(shards: Path) -> tuple[str, int]:
    """The tiny dataset's unseen scene and its class count."""
    manifest = read_manifest(shards)
    name = next(s for s, e in manifest.scenes.items() if e.meta["role"] == "test")
    return name, len(manifest.scenes[name].meta["class_names"])


def test_eval_samples_carry_the_stored_source_depth(tiny_shards: Path) -> None:
    scene, _ = _test_scene(tiny_shards)
    manifest = read_manifest(tiny_shards)
    views = read_scene_views(tiny_shards, manifest.scenes[scene])
    sample = next(make_eval_samples(tiny_shards, scene, n_source=N_SOURCE))
    ids = ranked_candidates(views[sample.query_id], set(manifest.scenes[scene].meta["splits"]["source"]), N_SOURCE)
    for i, view_id in enumerate(ids):
        assert torch.equal(sample.sources.rgb[i], torch.from_numpy(views[view_id].rgb()).permute(2, 0, 1) / 255.0)
        assert torch.equal(sample.sources.depth[i], torch.from_numpy(views[view_id].depth()))
    assert sample.sources.depth.dtype == torch.float32 and (sample.sources.depth > 0).any()


def test_resized_sources_keep_depth_aligned_and_unblended(tiny_shards: Path) -> None:
    scene, n_classes = _test_scene(tiny_shards)
    manifest = read_manifest(tiny_shards)
    views = read_scene_views(tiny_shards, manifest.scenes[scene])
    ids = sorted(views)[:4]
    sample = train_sample(views, ids[0], ids[1:], 16, np.random.default_rng(0), scene, 0.5, 6.0, n_classes,
                          Augmentation(source_scale=0.45))
    assert sample.sources.depth.shape == (3, *sample.sources.rgb.shape[-2:])
    for i, view_id in enumerate(ids[1:]):  # nearest pixel: every resized depth is one the view stored
        stored = set(np.unique(views[view_id].depth()).tolist())
        assert set(np.unique(sample.sources.depth[i].numpy()).tolist()) <= stored


def test_rescale_nearest_follows_the_pixel_centre_rule() -> None:
    depth = np.arange(16, dtype=np.float32).reshape(4, 4)
    assert rescale_nearest(depth, (4, 4)) is depth
    # doubling: output pixel u' has centre (u' + 0.5) / 2 - 0.5 -> input pixel u'//2 (ties never occur)
    up = rescale_nearest(depth, (8, 8))
    np.testing.assert_array_equal(up, depth[np.arange(8)[:, None] // 2, np.arange(8)[None, :] // 2])


def _renders(net: SRayModel, sample, stride: int = 4) -> tuple[torch.Tensor, torch.Tensor]:
    view = predict_view(sray_renderer(net, sample, torch.device("cpu")), sample, stride, 4096, torch.device("cpu"))
    return view.pred_label, view.pred_rgb


def test_the_query_depth_is_never_read(tiny_shards: Path) -> None:
    """Changing the query view's depth (to zeros, to noise) leaves the render bit-identical; changing the
    sources' depth changes it (so the depth the model reads is theirs)."""
    scene, n_classes = _test_scene(tiny_shards)
    sample = next(make_eval_samples(tiny_shards, scene, n_source=N_SOURCE))
    torch.manual_seed(0)
    net = SRayModel(SRayConfig(n_classes=n_classes, feat_dim=8, n_heads=2, n_coarse=8, n_fine=8, n_source=N_SOURCE,
                               geo_hidden=(16, 8), inputs="rgbd")).eval()
    label, rgb = _renders(net, sample)
    g = torch.Generator().manual_seed(1)
    for query_depth in (torch.zeros_like(sample.query_depth), 10 * torch.rand(sample.query_depth.shape, generator=g)):
        other = _renders(net, dataclasses.replace(sample, query_depth=query_depth))
        assert torch.equal(label, other[0]) and torch.equal(rgb, other[1])
    moved = dataclasses.replace(sample.sources, depth=sample.sources.depth * 0.7)
    assert not torch.equal(rgb, _renders(net, dataclasses.replace(sample, sources=moved))[1])


def test_set_model_inputs_and_its_refusal(tiny_shards: Path, tmp_path: Path) -> None:
    cfg = tiny_config(tiny_shards, tmp_path)
    apply_override(cfg, "model.inputs=rgbd")
    assert cfg.model.inputs == "rgbd"
    with pytest.raises(ValueError, match="`inputs` is 'depth'"):
        apply_override(cfg, "model.inputs=depth")
    assert cfg.model.inputs == "rgbd"  # rolled back


def test_validation_protocol_follows_the_model(tiny_shards: Path, tmp_path: Path) -> None:
    from sray.platform.train.validation import validation_protocol

    cfg = tiny_config(tiny_shards, tmp_path)
    assert validation_protocol(cfg).inputs == "rgb"
    cfg.model.inputs = "rgbd"
    protocol = validation_protocol(cfg)
    assert protocol.to_json()["inputs"] == "rgbd" and "inputs: rgbd" in protocol.describe()
    assert EvalProtocol.from_json(json.loads(json.dumps(protocol.to_json()))) == protocol
    with pytest.raises(ValueError, match="inputs is 'depth'"):
        dataclasses.replace(protocol, inputs="depth")


def _rgbd_checkpoint(shards: Path, root: Path) -> Path:
    """An untrained tiny S-Ray checkpoint with ``model.inputs = rgbd``, in a ``sray train`` job layout."""
    from sray.platform.checkpoints.folders import write_checkpoint
    from sray.platform.train.state import build_training, training_state

    cfg = tiny_config(shards, root)
    cfg.model.inputs = "rgbd"
    model, optimizer, scheduler = build_training(cfg)
    return write_checkpoint(training_state(model.net, optimizer, scheduler, None, 3, cfg, None, {}),
                            root / "jobs" / "rgbd" / "checkpoints" / "step_000000003", 3)


def test_a_finetune_of_an_rgbd_checkpoint_says_rgbd(tiny_shards: Path, tmp_path: Path) -> None:
    """The fleet's S-Ray finetune trains and scores with the sources' depth and records ``inputs: rgbd``."""
    from fleet_fixtures import tiny_fleet_config

    from sray.platform.finetune.scene_artifacts import checkpoint_sha256
    from sray.platform.finetune.scene_finetune import SceneTask, finetune_scene

    ckpt = _rgbd_checkpoint(tiny_shards, tmp_path)
    scene, _ = _test_scene(tiny_shards)
    task = SceneTask(scene=scene, method="sray", checkpoint=str(ckpt), base_sha256=checkpoint_sha256(ckpt),
                     shards=str(tiny_shards), out_dir=str(tmp_path / "ft"), run=None, attempt=1,
                     config=tiny_fleet_config(max_steps=2, eval_every=2))
    result = finetune_scene(task).result
    assert result["protocol"]["inputs"] == "rgbd" and result["steps_used"] == 2
    assert all(np.isfinite(p["miou"]) for p in result["curve"])


def test_sray_eval_of_an_rgbd_checkpoint_says_rgbd(tiny_shards: Path, tmp_path: Path, mlflow_uri: str) -> None:
    from sray.jobs.cli import main

    ckpt = _rgbd_checkpoint(tiny_shards, tmp_path)
    out = tmp_path / "eval"
    assert main(["eval", "--checkpoint", str(ckpt), "--data", str(tiny_shards), "--n-source", str(N_SOURCE),
                 "--stride", "8", "--out", str(out), "--tracking-uri", mlflow_uri]) == 0
    report = json.loads((out / "metrics.json").read_text())
    assert report["protocol"]["inputs"] == "rgbd"
