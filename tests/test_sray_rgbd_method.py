"""``sray-rgbd``, S-Ray given the source views' depth: the registry's one rule stands it beside every method that
reads depth (the fleet, the accuracy bench's comparison and the stability suite place it with that rule), a fleet task
finetunes the shared model in RGB-D mode, and its artifact reloads in that mode and reproduces its best score."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch
from fleet_fixtures import one_thread, tiny_checkpoint, tiny_fleet_config  # noqa: F401
from train_fixtures import tiny_shards  # noqa: F401

from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.shards.manifest import read_manifest
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.eval.view_scoring import score_scene, sray_renderer
from sray.platform.finetune.methods.registry import get_method, reads_depth, with_depth_twins
from sray.platform.finetune.scene_artifacts import checkpoint_sha256
from sray.platform.finetune.scene_finetune import SceneTask, finetune_scene

SCENE = "synth_test_000"
CPU = torch.device("cpu")
IGNORE = 255


def test_the_depth_twin_stands_just_before_the_first_method_that_reads_depth() -> None:
    assert with_depth_twins(["sray", "semantic-nerf"]) == ["sray", "semantic-nerf"]  # nothing reads depth
    assert with_depth_twins(["sray", "2d-transfer", "sray"]) == ["sray", "sray-rgbd", "2d-transfer"]
    assert with_depth_twins(["2d-transfer", "semantic-nerf"]) == ["sray-rgbd", "2d-transfer", "semantic-nerf"]
    assert with_depth_twins(["2d-transfer", "sray-rgbd"]) == ["2d-transfer", "sray-rgbd"]  # asked for: kept there
    assert with_depth_twins(["sray-rgbd"]) == ["sray-rgbd"]
    # a checkpoint that reads the depth already is its own twin
    assert with_depth_twins(["sray", "2d-transfer"], "rgbd") == ["sray", "2d-transfer"]
    assert with_depth_twins(["2d-transfer"], "rgbd") == ["sray", "2d-transfer"]
    assert [reads_depth(m) for m in ("sray", "semantic-nerf", "sray-rgbd", "2d-transfer")] == [False] * 3 + [True]


def test_a_fleet_task_finetunes_sray_given_the_source_depth(tiny_shards: Path, tiny_checkpoint: Path,
                                                            tmp_path: Path, one_thread: None) -> None:
    """Step 0 is the shared model given the source depth, scored by hand here (and not the RGB model's score); the
    protocol says RGB-D; the stored artifact reloads in RGB-D mode and reproduces the best held-out score."""
    method = get_method("sray-rgbd")
    cfg = tiny_fleet_config(max_steps=2, eval_every=2, patience=5)
    job = SceneTask(scene=SCENE, method=method.name, checkpoint=str(tiny_checkpoint),
                    base_sha256=checkpoint_sha256(tiny_checkpoint), shards=str(tiny_shards), out_dir=str(tmp_path),
                    run=None, attempt=1, config=cfg)
    result = finetune_scene(job).result
    assert result["status"] == "finished" and [p["step"] for p in result["curve"]] == [0, 2]
    assert (result["protocol"]["inputs"], result["protocol"]["n_source"]) == ("rgbd", 3)

    ft, n_classes = cfg.finetune, len(read_manifest(tiny_shards).scenes[SCENE].meta["class_names"])
    samples = list(make_eval_samples(tiny_shards, SCENE, split="test", n_source=ft.held_out.n_source))

    def held_out(net: torch.nn.Module) -> dict[str, float]:
        return score_scene(lambda s: sray_renderer(net, s, CPU, ft.held_out.fast()), samples, n_classes, IGNORE,
                           ft.held_out.stride, ft.eval_chunk, CPU, ft.held_out.fast()).scores

    with torch.no_grad():
        rgb = model_from_checkpoint(tiny_checkpoint)[0].eval()
        assert rgb.cfg.inputs == "rgb"
        rgb_scores = held_out(rgb)
        rgb.cfg = dataclasses.replace(rgb.cfg, inputs="rgbd")
        depth_scores = held_out(rgb)
        assert result["curve"][0]["psnr"] == pytest.approx(depth_scores["psnr"], abs=1e-6)
        assert result["curve"][0]["psnr"] != pytest.approx(rgb_scores["psnr"], abs=1e-3)  # the depth placed samples
        stored = method.load_artifact(tmp_path, tiny_checkpoint)
        assert stored.cfg.inputs == "rgbd" and not stored.training
        assert result["psnr_after"] == pytest.approx(held_out(stored)["psnr"], abs=1e-6)
        assert result["miou_after"] == pytest.approx(held_out(stored)["miou"], abs=1e-9)
