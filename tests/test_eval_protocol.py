"""The protocol descriptor: read from the shard manifest, its JSON shape, captions, SSIM on whole images only."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from train_fixtures import tiny_shards  # noqa: F401  (pytest fixture, used by name)

from sray.jobs.cli import build_parser
from sray.jobs.train_cmd import build_config
from sray.platform.common.eval_protocol import EvalProtocol, caption_lines
from sray.platform.config.train_config import TrainConfig
from sray.platform.eval.view_scoring import ViewPrediction, score_views
from sray.platform.train.job_loader import job_loader
from sray.platform.train.validation import validation_protocol

JSON_KEYS = {"source_rule", "n_source", "stride", "render", "inputs", "train_inputs", "miou", "miou_per_image"}
"""docs/CONTRACTS.md, "Protocol descriptor"."""


def test_source_rule_is_the_manifests_neighbour_rule(tiny_shards: Path) -> None:
    raw = json.loads((tiny_shards / "manifest.json").read_text())["neighbours"]
    protocol = EvalProtocol.from_shards(tiny_shards, n_source=3, stride=2)
    assert protocol.source_rule == f"{raw['rule']} v{raw['version']}"
    assert protocol.to_json() == {"source_rule": f"{raw['rule']} v{raw['version']}", "n_source": 3, "stride": 2,
                                  "render": "full", "inputs": "rgb", "train_inputs": "rgb",
                                  "miou": "dataset-level, classes present in ground truth",
                                  "miou_per_image": "per-image mean"}


def test_a_manifest_without_a_rule_is_refused(tiny_shards: Path) -> None:
    from sray.data_tools.shards.manifest import read_manifest

    manifest = read_manifest(tiny_shards)
    manifest.neighbours = {"k": 8}
    with pytest.raises(ValueError, match="field 'neighbours' has no 'rule'"):
        EvalProtocol.from_manifest(manifest, 3, 1)


def test_json_round_trip_and_refusals() -> None:
    protocol = EvalProtocol(source_rule="frustum-overlap v1", n_source=8, stride=1)
    as_json = json.loads(json.dumps(protocol.to_json()))
    assert set(as_json) == JSON_KEYS and EvalProtocol.from_json(as_json) == protocol
    with pytest.raises(ValueError, match=r"\['stride'\] missing"):
        EvalProtocol.from_json({k: v for k, v in as_json.items() if k != "stride"})
    with pytest.raises(ValueError, match="expected a JSON object"):
        EvalProtocol.from_json("mIoU over held-out views")  # type: ignore[arg-type]
    for bad, field in (({"stride": 0}, "stride"), ({"render": "sparse"}, "render"), ({"inputs": "rgb+lidar"}, "inputs"),
                       ({"n_source": 0}, "n_source"), ({"train_inputs": "depth"}, "train_inputs")):
        with pytest.raises(ValueError, match=field):
            EvalProtocol(**(as_json | bad))


def test_training_depth_is_recorded_and_old_descriptors_still_load(tiny_shards: Path) -> None:
    """``sray train --set model.lambda_depth=0.1``, as the workers receive it: the rank's loader delivers the query
    pixels' depth and the validation protocol's ``train_inputs`` is ``rgbd`` (named in the describe line, while the
    test inputs stay ``rgb``); without it, no depth and ``rgb`` with the unchanged line. A descriptor stored before
    the field existed loads with training inputs = its inputs."""
    protocols = {}
    for weight in (0.0, 0.1):
        args = build_parser().parse_args(["train", "--data", str(tiny_shards), "--set", f"model.lambda_depth={weight}",
                                          "--set", "model.n_source=3"])
        cfg = TrainConfig.from_dict(json.loads(json.dumps(build_config(args).to_dict())))
        sample = next(iter(job_loader(cfg, rank=0, world_size=1, batches_per_epoch=1)))
        assert (sample.target_depth is not None) == (weight > 0)
        protocols[weight] = validation_protocol(cfg)
    off, on = protocols[0.0], protocols[0.1]
    assert (off.inputs, off.train_inputs, on.inputs, on.train_inputs) == ("rgb", "rgb", "rgb", "rgbd")
    assert "training read" not in off.describe() and "inputs: rgb (training read rgbd)" in on.describe()
    assert EvalProtocol.from_json(json.loads(json.dumps(on.to_json()))) == on
    old = {k: v for k, v in off.to_json().items() if k != "train_inputs"}
    assert EvalProtocol.from_json(old) == off
    assert EvalProtocol.from_json(old | {"inputs": "rgbd"}).train_inputs == "rgbd"


def test_describe_names_stride_and_ssim() -> None:
    whole = EvalProtocol(source_rule="frustum-overlap v1", n_source=8, stride=1)
    strided = EvalProtocol(source_rule="frustum-overlap v1", n_source=8, stride=4)
    assert whole.scores_ssim and not strided.scores_ssim
    assert "whole images (stride 1)" in whole.describe() and "SSIM" not in whole.describe()
    assert "every 4th in each direction (stride 4), so no SSIM" in strided.describe()
    assert "8 per query" in whole.describe() and "frustum-overlap v1" in whole.describe()
    nerf = EvalProtocol.without_sources(4)
    assert nerf.n_source == 0 and "none (per-scene model)" in nerf.describe()
    for protocol in (whole, strided, nerf):
        assert "\n" not in protocol.describe()


def test_caption_lines_group_rows_by_protocol() -> None:
    sray = EvalProtocol(source_rule="frustum-overlap v1", n_source=3, stride=2).to_json()
    nerf = EvalProtocol.without_sources(2).to_json()
    [one] = caption_lines([("a", sray), ("b", sray), ("c", None)])
    assert one.startswith("Protocol: sources: 3 per query") and "stride 2" in one
    two = caption_lines([("sray", sray), ("semantic-nerf", nerf), ("sray", sray)])
    assert [line.split(":")[0] for line in two] == ["Protocol (sray)", "Protocol (semantic-nerf)"]
    assert caption_lines([("a", None)]) == []


def _view(rgb: torch.Tensor, stride: int) -> ViewPrediction:
    h, w = rgb.shape[:2]
    labels = torch.arange(h * w).reshape(h, w) % 3
    return ViewPrediction(query_id="v", pred_label=labels, pred_rgb=rgb, gt_label=labels, gt_rgb=rgb, stride=stride)


def test_ssim_only_for_whole_images() -> None:
    rgb = torch.rand(16, 20, 3, generator=torch.Generator().manual_seed(0))
    whole = score_views([_view(rgb, 1), _view(rgb, 1)], n_classes=3, ignore_id=255)
    assert whole["ssim"] == pytest.approx(1.0, abs=1e-12)  # a perfect render
    strided = score_views([_view(rgb, 2)], n_classes=3, ignore_id=255)
    assert "ssim" not in strided and strided["miou"] == 1.0
