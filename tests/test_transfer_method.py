"""The ``2d-transfer`` method: its source-depth splatting on a hand-built two-view scene with an occluder (expected
labels derived by hand), that it reads nothing of the query view but its camera (poisoned query data change
nothing), a fleet task end to end (step 0 = ``sray eval``'s zero-shot score, the stored artifact reproduces the
best score), and ``sray eval --method 2d-transfer`` on the tiny shards against an independent count.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from fleet_fixtures import kept_point, one_thread, tiny_checkpoint, tiny_fleet_config, tiny_segmenter  # noqa: F401
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: F401
from torch import Tensor
from train_fixtures import tiny_shards  # noqa: F401

from sray.data_tools.loader.sample_types import EvalSample, QueryCamera, SourceViews
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.shards.manifest import read_manifest
from sray.jobs.cli import main
from sray.lab.ceilings.rows import CeilingRow, RowProtocol
from sray.model.view_render import render_view
from sray.platform.eval.eval_model import segmenter_model
from sray.platform.eval.label_transfer import UNSEEN, transfer_labels
from sray.platform.eval.segmenter import (Segmenter, SegmenterConfig, load_segmenter, segment_and_transfer,
                                          transfer_renderer)
from sray.platform.eval.view_scoring import predict_view, score_scene, score_views
from sray.platform.finetune.learners import TransferLearner
from sray.platform.finetune.methods.registry import get_method
from sray.platform.finetune.scene_artifacts import checkpoint_sha256
from sray.platform.finetune.scene_finetune import SceneTask, finetune_scene
from sray.platform.viz.palette import IGNORE_COLOR, palette
from sray.platform.viz.renders import ERROR_COLOR

pytestmark = pytest.mark.usefixtures("one_thread")

SCENE = "synth_test_000"
CPU = torch.device("cpu")
IGNORE = 255

# The hand-built scene: a wall (plane z = 4, class WALL) behind a vertical strip (z = 2, |x| <= 0.25, class STRIP),
# seen by a query camera at the origin and a source camera 0.5 m to its right, both looking along +z (OpenCV axes),
# f = 40 px, 24 x 48 images. The red channel of a pixel is its class / 10 (what ColourSegmenter reads).
WALL, STRIP = 1, 2
H, W, F_PX = 24, 48, 40.0
WALL_Z, STRIP_Z, STRIP_HALF, SOURCE_X = 4.0, 2.0, 0.25, 0.5


class ColourSegmenter(Segmenter):
    """A segmenter whose prediction is known: class round(10 * red) at every pixel (test double)."""

    def __init__(self) -> None:
        super().__init__(SegmenterConfig(n_classes=3, ignore_id=IGNORE))

    def forward(self, rgb: Tensor) -> Tensor:
        """One-hot logits (B, 3, H, W) of rgb (B, 3, H, W)."""
        return F.one_hot((rgb[:, 0] * 10).round().long(), 3).permute(0, 3, 1, 2).float()


def strip_view(eye_x: float) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """rgb (3, H, W), depth (H, W), label (H, W), K (3, 3) and c2w (4, 4) of a camera at (eye_x, 0, 0)."""
    K = torch.tensor([[F_PX, 0, (W - 1) / 2], [0, F_PX, (H - 1) / 2], [0, 0, 1]], dtype=torch.float32)
    c2w = torch.eye(4)
    c2w[0, 3] = eye_x
    u = torch.arange(W, dtype=torch.float64)
    on_strip = (eye_x + STRIP_Z * (u - K[0, 2].double()) / F_PX).abs() <= STRIP_HALF  # (W,)
    label = torch.where(on_strip, STRIP, WALL).expand(H, W)
    depth = torch.where(on_strip, STRIP_Z, WALL_Z).float().expand(H, W)
    rgb = torch.stack([label / 10, torch.full((H, W), 0.5), torch.full((H, W), 0.5)]).float()
    return rgb, depth, label, K, c2w


def strip_sample() -> EvalSample:
    """The two-view scene as an evaluation sample: the source at x = 0.5, the query at the origin."""
    s_rgb, s_depth, _, s_K, s_c2w = strip_view(SOURCE_X)
    q_rgb, q_depth, q_label, q_K, q_c2w = strip_view(0.0)
    return EvalSample(scene="strip", query_id="q", near=1.0, far=5.0,
                      sources=SourceViews(rgb=s_rgb[None], K=s_K[None], c2w=s_c2w[None], depth=s_depth[None]),
                      query=QueryCamera(K=q_K, c2w=q_c2w), query_rgb=q_rgb.permute(1, 2, 0), query_label=q_label,
                      query_depth=q_depth)


def expected_strip_row() -> Tensor:
    """Each query row by hand. The wall shifts 40 * 0.5 / 4 = 5 px between the views, the strip 10 px: query
    pixel u shows wall point (u - 23.5) / 10 or strip point (u - 23.5) / 20. Columns 0-4: their wall points lie
    left of the source's frame (source column u - 5 < 0). Columns 5-13: wall both views see. Columns 14-18: wall
    x in [-0.95, -0.55], which the strip hides from the source (its shadow from x = 0.5 covers [-1, 0]): no label.
    Columns 19-28: the strip (the wall behind it, which the source sees, lands there too and loses the z-test).
    Columns 29-47: wall."""
    return torch.tensor([UNSEEN] * 5 + [WALL] * 9 + [UNSEEN] * 5 + [STRIP] * 10 + [WALL] * 19)


def test_source_depth_splatting_sees_the_strip_and_leaves_the_hidden_wall_unlabelled() -> None:
    """The transfer of the two-view scene equals the hand derivation; the method's renderer and the held-out
    scoring keep the unlabelled pixels as misses of their true class, scored exactly as ceilings row c scores
    them; colours are carried from the source (black where it sees nothing)."""
    sample, seg = strip_sample(), ColourSegmenter()
    out = segment_and_transfer(seg, sample.sources, sample.query, 0.05)
    expected = expected_strip_row().expand(H, W)
    torch.testing.assert_close(out.labels, expected, rtol=0, atol=0)
    torch.testing.assert_close(out.seen, expected != UNSEEN, rtol=0, atol=0)

    view = predict_view(transfer_renderer(seg, sample, 0.05, CPU), sample, stride=1, chunk=0, device=CPU)
    torch.testing.assert_close(view.pred_label, expected, rtol=0, atol=0)
    torch.testing.assert_close(view.pred_rgb[0, :, 0], torch.where(expected[0] == UNSEEN, 0.0, expected[0] / 10),
                               rtol=0, atol=1e-6)
    scores = score_views([view], 3, IGNORE)
    # wall: 38 px per row, 28 predicted (the 10 unlabelled are misses, no class's false positives); strip: 10 of 10
    assert scores["miou"] == pytest.approx((28 / 38 + 1) / 2, abs=1e-12)
    assert scores["total_acc"] == pytest.approx(38 / 48, abs=1e-12)
    row = CeilingRow("c", "2d-transfer", RowProtocol("segmenter", "forward"))
    row.add("strip", out.labels, sample.query_label, 3, IGNORE, 0.0, out.seen)
    summary = row.summary(3)
    assert (summary["miou"], summary["total_acc"]) == pytest.approx((scores["miou"], scores["total_acc"]), abs=1e-12)


def poisoned(sample: EvalSample) -> EvalSample:
    """``sample`` with NaN query colours and depth and random query labels."""
    gen = torch.Generator().manual_seed(0)
    return dataclasses.replace(sample, query_rgb=torch.full_like(sample.query_rgb, float("nan")),
                               query_depth=torch.full_like(sample.query_depth, float("nan")),
                               query_label=torch.randint(0, 255, sample.query_label.shape, generator=gen))


def rendered(renderer, sample: EvalSample) -> dict[str, Tensor]:
    """Fine logits and colours of every pixel of the sample's query view."""
    h, w = sample.query_label.shape
    return render_view(renderer, sample.query.K, sample.query.c2w, (h, w), sample.near, sample.far, 0, CPU,
                       passes=("fine",), keys=("logits", "rgb"))["fine"]


def test_no_query_view_data_is_read(tiny_shards: Path, tiny_segmenter: Path) -> None:
    """The method's renderers (``sray eval``'s and the fleet learner's) give identical outputs when the query view's
    colours, depth and labels are poisoned; the poison would change an oracle that reads the query depth."""
    model = segmenter_model(tiny_segmenter, "cpu")
    segmenter, _ = load_segmenter(tiny_segmenter)
    learner = TransferLearner(segmenter, 1e-3, 1.0, "no", CPU, 5, 0.05)
    for sample in list(make_eval_samples(tiny_shards, SCENE, split="test", n_source=3))[:2]:
        bad = poisoned(sample)
        for make in (model.renderer, learner.renderer):
            clean, dirty = rendered(make(sample), sample), rendered(make(bad), bad)
            assert torch.isfinite(clean["logits"]).any(-1).float().mean() > 0.5  # most pixels get a label
            torch.testing.assert_close(dirty, clean, rtol=0, atol=0)
        src, q = sample.sources, sample.query
        oracle = [transfer_labels(segmenter.predict(src.rgb), src.K, src.c2w, src.depth, q.K, q.c2w,
                                  tuple(s.query_depth.shape), "backward", query_depth=s.query_depth).labels
                  for s in (sample, bad)]
        assert not torch.equal(*oracle)


def test_a_fleet_task_finetunes_the_segmenter_and_stores_it(tiny_shards: Path, tiny_checkpoint: Path,
                                                            tiny_segmenter: Path, tmp_path: Path) -> None:
    """``2d-transfer`` is registered and runs through a fleet task: its step-0 score is the pretrained segmenter's
    zero-shot score under the fleet's protocol (RGB-D, full render), the artifact reloads through ``Method.load``
    and reproduces the best held-out score."""
    method = get_method("2d-transfer")
    cfg = tiny_fleet_config(max_steps=4, eval_every=2, patience=5)
    cfg = method.checked_config(dataclasses.replace(cfg, transfer=dataclasses.replace(
        cfg.transfer, segmenter=os.path.relpath(tiny_segmenter), images_per_step=2)))
    assert cfg.transfer.segmenter == str(tiny_segmenter.resolve())  # tasks get an absolute path
    job = SceneTask(scene=SCENE, method="2d-transfer", checkpoint=str(tiny_checkpoint),
                    base_sha256=checkpoint_sha256(tiny_checkpoint), shards=str(tiny_shards), out_dir=str(tmp_path),
                    run=None, attempt=1, config=cfg)
    result = finetune_scene(job).result
    assert result["status"] == "finished" and result["steps_used"] == 4
    assert [p["step"] for p in result["curve"]] == [0, 2, 4]
    protocol = result["protocol"]
    assert (protocol["inputs"], protocol["render"], protocol["n_source"]) == ("rgbd", "full", 3)

    ft, n_classes = cfg.finetune, len(read_manifest(tiny_shards).scenes[SCENE].meta["class_names"])
    samples = list(make_eval_samples(tiny_shards, SCENE, split="test", n_source=ft.held_out.n_source))

    def held_out(segmenter: Segmenter) -> float:
        return score_scene(lambda s: transfer_renderer(segmenter, s, 0.05, CPU), samples, n_classes, IGNORE,
                           ft.held_out.stride, 0, CPU).scores["miou"]

    assert result["miou_before"] == pytest.approx(held_out(load_segmenter(tiny_segmenter)[0]), abs=1e-9)
    stored = method.load_artifact(tmp_path, tiny_checkpoint)
    assert isinstance(stored, Segmenter) and not stored.training
    assert result["artifact_bytes"] == (tmp_path / "segmenter.safetensors").stat().st_size
    assert result["miou_after"] == pytest.approx(held_out(stored), abs=1e-9)
    kept = kept_point(result["curve"], cfg.finetune.min_delta)  # the best by the early-stop rule, not the max
    assert result["miou_after"] == kept["miou"] > result["miou_before"]  # it learned


def test_the_fleet_refuses_2d_transfer_without_a_segmenter(tiny_shards: Path, tiny_checkpoint: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Before anything starts, the fleet names the missing setting and the fix, or the missing segmenter file."""
    args = ["finetune-fleet", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--scenes", SCENE,
            "--methods", "2d-transfer", "--out", str(tmp_path / "fleet"),
            "--tracking-uri", f"sqlite:///{tmp_path / 'mlflow.db'}"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "transfer.segmenter is empty" in err and "--segmenter FOLDER" in err
    assert main([*args, "--segmenter", str(tmp_path / "nowhere")]) == 2
    assert "nowhere/segmenter.json: missing" in capsys.readouterr().err
    assert not (tmp_path / "fleet").exists()


def naive_scores(pairs: list[tuple[np.ndarray, np.ndarray]]) -> tuple[float, float]:
    """(mIoU over the classes present in the ground truth, total accuracy), counted pixel by pixel; a pixel without
    prediction (UNSEEN) is a miss of its true class and a false positive of none."""
    tp: dict[int, int] = {}
    fp: dict[int, int] = {}
    fn: dict[int, int] = {}
    for pred, gt in pairs:
        for p, g in zip(pred.ravel().tolist(), gt.ravel().tolist()):
            if g == IGNORE:
                continue
            if p == g:
                tp[g] = tp.get(g, 0) + 1
                continue
            fn[g] = fn.get(g, 0) + 1
            if p != UNSEEN:
                fp[p] = fp.get(p, 0) + 1
    present = set(tp) | set(fn)
    ious = [tp.get(c, 0) / (tp.get(c, 0) + fp.get(c, 0) + fn.get(c, 0)) for c in present]
    return sum(ious) / len(ious), sum(tp.values()) / (sum(tp.values()) + sum(fn.values()))


def test_sray_eval_scores_2d_transfer_zero_shot(tiny_shards: Path, tiny_segmenter: Path, mlflow_uri: str,
                                                tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``sray eval --method 2d-transfer --segmenter S`` on the tiny shards: the descriptor says RGB-D, the scores
    equal a pixel count of the segmenter's source labels splatted by ``transfer_labels`` itself, unlabelled pixels
    are blank in the prediction PNG and errors in the error map; bad requests exit 2 naming the flag."""
    out, stride = tmp_path / "eval", 2
    code = main(["eval", "--method", "2d-transfer", "--segmenter", str(tiny_segmenter), "--data", str(tiny_shards),
                 "--n-source", "3", "--stride", str(stride), "--out", str(out), "--tracking-uri", mlflow_uri])
    printed = capsys.readouterr().out
    assert code == 0
    report = json.loads((out / "metrics.json").read_text())
    assert report["method"] == "2d-transfer" and report["segmenter"]["folder"] == str(tiny_segmenter.resolve())
    assert "checkpoint" not in report
    assert (report["protocol"]["inputs"], report["protocol"]["render"]) == ("rgbd", "full")
    assert "inputs: rgbd" in printed

    segmenter, _ = load_segmenter(tiny_segmenter)
    block, pairs, unseen = report["scenes"][SCENE], [], 0
    samples = make_eval_samples(tiny_shards, SCENE, split="test", n_source=3)
    colours = {tuple(int(v) for v in c): i for i, c in enumerate(palette(segmenter.cfg.n_classes))}
    for view, sample in zip(block["views"], samples, strict=True):
        src, q, off = sample.sources, sample.query, stride // 2
        expected = transfer_labels(segmenter.predict(src.rgb), src.K, src.c2w, src.depth, q.K, q.c2w,
                                   tuple(src.depth.shape[-2:]), "forward").labels.numpy()[off::stride, off::stride]
        gt = sample.query_label.numpy()[off::stride, off::stride]
        png = cv2.cvtColor(cv2.imread(str(out / view["pngs"]["pred"])), cv2.COLOR_BGR2RGB)
        blank = np.all(png == IGNORE_COLOR, axis=-1)
        np.testing.assert_array_equal(blank, expected == UNSEEN)
        decoded = np.vectorize(lambda r, g, b: colours.get((r, g, b), UNSEEN))(png[..., 0], png[..., 1], png[..., 2])
        np.testing.assert_array_equal(decoded, expected)
        error = cv2.cvtColor(cv2.imread(str(out / view["pngs"]["error"])), cv2.COLOR_BGR2RGB)
        assert np.all(error == ERROR_COLOR, axis=-1)[(expected == UNSEEN) & (gt != IGNORE)].all()
        unseen += int(((expected == UNSEEN) & (gt != IGNORE)).sum())
        pairs.append((expected, gt))
    assert unseen > 0  # some labelled query pixels are seen by no source: the rule is exercised
    miou, total = naive_scores(pairs)
    assert block["dataset_level"]["miou"] == pytest.approx(miou, abs=1e-9)
    assert block["dataset_level"]["total_acc"] == pytest.approx(total, abs=1e-9)

    base = ["eval", "--data", str(tiny_shards), "--out", str(tmp_path / "bad"), "--tracking-uri", mlflow_uri]
    assert main([*base, "--method", "2d-transfer"]) == 2
    assert "pass --segmenter FOLDER" in capsys.readouterr().err
    assert main(base) == 2  # the default method, S-Ray, needs a checkpoint
    assert "pass --checkpoint FOLDER" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # Semantic-NeRF trains per scene: it has no model to evaluate
        main([*base, "--method", "semantic-nerf"])
