"""The protocol descriptor: read from the shard manifest, its JSON shape, captions, SSIM on whole images only."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from train_fixtures import tiny_shards  # noqa: F401  (pytest fixture, used by name)

from sray.platform.common.eval_protocol import EvalProtocol, caption_lines
from sray.platform.eval.view_scoring import ViewPrediction, score_views

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


def test_training_inputs_are_named_and_old_descriptors_still_load() -> None:
    """A protocol whose training read depth its test inputs lack (a scene finetune of ``sray-rgbd``) names it in the
    describe line; the same inputs leave the line unchanged. A descriptor stored before ``train_inputs`` existed
    loads with training inputs = its inputs."""
    off = EvalProtocol("frustum-overlap v1", 8, 1, inputs="rgb")
    on = EvalProtocol("frustum-overlap v1", 8, 1, inputs="rgb", train_inputs="rgbd")
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
