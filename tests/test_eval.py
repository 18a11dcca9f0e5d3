"""``sray eval`` on a tiny unseen scene: metrics.json (both protocols), PNGs, and the MLflow run.

The scores in metrics.json are checked against an independent count: the predicted and ground-truth
semantic PNGs are decoded back to class ids through the palette and scored with a naive loop. The
protocol descriptor is checked against the raw manifest.json and the command line: a strided
evaluation has no SSIM, a whole-image one has.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: E402,F401  (pytest fixtures, used by name)
from train_fixtures import tiny_config, tiny_shards  # noqa: E402,F401

from sray.data_tools.loader.shard_loader import make_eval_samples  # noqa: E402
from sray.data_tools.shards.manifest import read_manifest  # noqa: E402
from sray.model.fast_render import FastRender  # noqa: E402
from sray.model.metrics import DATASET_PROTOCOL, LPIPS_NOTE, PER_IMAGE_PROTOCOL  # noqa: E402
from sray.model.ssim import SSIM_WINDOW  # noqa: E402
from sray.platform.viz.palette import IGNORE_COLOR, palette  # noqa: E402
from sray.platform.viz.renders import CORRECT_COLOR, ERROR_COLOR  # noqa: E402

N_SOURCE, STRIDE = 3, 2


@pytest.fixture(scope="module")
def tiny_checkpoint(tiny_shards, tmp_path_factory) -> Path:
    """An untrained tiny S-Ray checkpoint in a ``sray train`` job layout."""
    from sray.platform.checkpoints.folders import write_checkpoint
    from sray.platform.train.state import build_training, training_state

    root = tmp_path_factory.mktemp("eval-ckpt")
    cfg = tiny_config(tiny_shards, root)
    model, optimizer, scheduler = build_training(cfg)
    state = training_state(model.net, optimizer, scheduler, None, 12, cfg, None, {})
    return write_checkpoint(state, root / "jobs" / "tiny" / "checkpoints" / "step_000000012", 12)


def _decode(png: Path, n_classes: int, ignore_id: int) -> np.ndarray:
    """Class ids (H, W) of a colourised semantic PNG (every pixel must be a palette colour)."""
    rgb = cv2.cvtColor(cv2.imread(str(png)), cv2.COLOR_BGR2RGB)
    table = {tuple(int(v) for v in c): i for i, c in enumerate(palette(n_classes))}
    table[IGNORE_COLOR] = ignore_id
    ids = np.vectorize(lambda r, g, b: table.get((r, g, b), -1))(rgb[..., 0], rgb[..., 1], rgb[..., 2])
    assert (ids >= 0).all(), f"{png} holds colours outside the palette"
    return ids


def _naive_class_iou(pairs: list[tuple[np.ndarray, np.ndarray]], ignore_id: int) -> dict[int, float]:
    """IoU of each class present in the ground truth of ``pairs``, counted pixel by pixel."""
    tp, fp, fn, present = {}, {}, {}, set()
    for pred, gt in pairs:
        for p, g in zip(pred.ravel().tolist(), gt.ravel().tolist()):
            if g == ignore_id:
                continue
            present.add(g)
            if p == g:
                tp[g] = tp.get(g, 0) + 1
            else:
                fn[g] = fn.get(g, 0) + 1
                fp[p] = fp.get(p, 0) + 1
    return {c: tp.get(c, 0) / (tp.get(c, 0) + fp.get(c, 0) + fn.get(c, 0)) for c in present}


def _naive_iou(pairs: list[tuple[np.ndarray, np.ndarray]], ignore_id: int) -> float:
    """mIoU over the classes present in the ground truth of ``pairs``."""
    ious = list(_naive_class_iou(pairs, ignore_id).values())
    return sum(ious) / len(ious)


def _expected_protocol(shards: Path, n_source: int, stride: int, render: str) -> dict:
    """The descriptor an evaluation of ``shards`` must carry, from the raw manifest and the arguments."""
    rule = json.loads((shards / "manifest.json").read_text())["neighbours"]
    return {"source_rule": f"{rule['rule']} v{rule['version']}", "n_source": n_source, "stride": stride,
            "render": render, "inputs": "rgb", "train_inputs": "rgb", "miou": DATASET_PROTOCOL,
            "miou_per_image": PER_IMAGE_PROTOCOL}


def test_eval_writes_both_protocols_pngs_and_an_mlflow_run(tiny_checkpoint, tiny_shards, mlflow_uri, tmp_path,
                                                           capsys):
    from mlflow import MlflowClient

    from sray.jobs.cli import main

    out = tmp_path / "eval"
    code = main(["eval", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--n-source",
                 str(N_SOURCE), "--stride", str(STRIDE), "--out", str(out), "--tracking-uri", mlflow_uri])
    printed = capsys.readouterr().out
    assert code == 0
    report = json.loads((out / "metrics.json").read_text())
    manifest = read_manifest(tiny_shards)
    test_scenes = sorted(s for s, e in manifest.scenes.items() if e.meta["role"] == "test")
    assert list(report["scenes"]) == test_scenes and report["checkpoint_step"] == 12
    assert report["lpips"] == LPIPS_NOTE
    # the default render is the fast mode with FastRender's default settings, and the descriptor says so
    assert report["protocol"] == _expected_protocol(tiny_shards, N_SOURCE, STRIDE, FastRender().describe())
    assert FastRender().describe().startswith("fast (pixel stride 8, fine pass where the coarse confidence < 0.9")
    assert not {"stride", "n_source"} & set(report)  # the descriptor holds them, once

    for scene in test_scenes:
        block, meta = report["scenes"][scene], manifest.scenes[scene].meta
        n_classes, ignore_id = len(meta["class_names"]), meta["ignore_id"]
        assert block["dataset_level"]["protocol"] == DATASET_PROTOCOL
        assert block["per_image"]["protocol"] == PER_IMAGE_PROTOCOL
        assert block["colour"]["ssim_window"] == SSIM_WINDOW and block["n_views"] == len(meta["splits"]["test"])
        assert block["colour"]["ssim"] is None  # strided renders never get an SSIM
        samples = list(make_eval_samples(tiny_shards, scene, split="test", n_source=N_SOURCE))
        pairs = []
        for view, sample in zip(block["views"], samples, strict=True):
            pngs = {k: out / v for k, v in view["pngs"].items()}
            assert all(p.is_file() for p in pngs.values()) and view["query_id"] == sample.query_id
            gt_full = sample.query_label.numpy()
            gt = _decode(pngs["gt"], n_classes, ignore_id)
            off = STRIDE // 2  # the strided grid samples pixel centres (off, off), (off + STRIDE, off) ...
            np.testing.assert_array_equal(gt, gt_full[off::STRIDE, off::STRIDE])
            pred = _decode(pngs["pred"], n_classes, ignore_id)
            assert (pred != ignore_id).all()  # a prediction is always a class
            error = cv2.cvtColor(cv2.imread(str(pngs["error"])), cv2.COLOR_BGR2RGB)
            wrong = (gt != ignore_id) & (pred != gt)
            np.testing.assert_array_equal(np.all(error == ERROR_COLOR, axis=-1), wrong)
            np.testing.assert_array_equal(np.all(error == CORRECT_COLOR, axis=-1), (gt != ignore_id) & ~wrong)
            panel = cv2.imread(str(pngs["panel"]))
            assert panel is not None and panel.shape[0] > 3 * gt.shape[0]
            assert view["miou_per_image"] == pytest.approx(_naive_iou([(pred, gt)], ignore_id), abs=1e-9)
            pairs.append((pred, gt))
        assert block["dataset_level"]["miou"] == pytest.approx(_naive_iou(pairs, ignore_id), abs=1e-9)
        per_class = _naive_class_iou(pairs, ignore_id)
        assert len(block["dataset_level"]["iou_per_class"]) == n_classes
        for c, iou in enumerate(block["dataset_level"]["iou_per_class"]):
            assert iou is None if c not in per_class else iou == pytest.approx(per_class[c], abs=1e-9)
        assert block["per_image"]["miou"] == pytest.approx(np.mean([v["miou_per_image"] for v in block["views"]]),
                                                           abs=1e-9)
        right = sum(int(((p == g) & (g != ignore_id)).sum()) for p, g in pairs)
        assert block["dataset_level"]["total_acc"] == pytest.approx(
            right / sum(int((g != ignore_id).sum()) for _, g in pairs), abs=1e-9)
        assert 0.0 < block["colour"]["psnr_db"] < 60.0

    mean = report["mean"]
    for key in ("miou", "total_acc", "class_avg_acc"):
        assert mean["dataset_level"][key] == pytest.approx(
            np.mean([report["scenes"][s]["dataset_level"][key] for s in test_scenes]), abs=1e-12)
    assert mean["n_scenes"] == len(test_scenes) and mean["per_image"]["protocol"] == PER_IMAGE_PROTOCOL
    assert mean["colour"]["ssim"] is None

    # the printed table: no SSIM column for a strided evaluation, the protocol line under it
    header = next(line for line in printed.splitlines() if line.startswith("scene "))
    assert "mIoU/img" in header and "SSIM" not in header
    assert f"stride {STRIDE}), so no SSIM" in printed and f"sources: {N_SOURCE} per query" in printed

    # the printed table and locations
    assert f"metrics: {out.resolve() / 'metrics.json'}" in printed
    assert all(scene in printed for scene in test_scenes) and "sray ui --tracking-uri" in printed

    # the MLflow run holds the same numbers, metrics.json and the PNGs
    client = MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("sray-eval")
    (run,) = client.search_runs([experiment.experiment_id])
    assert run.info.status == "FINISHED" and run.data.tags["sray.kind"] == "eval"
    assert f"stride {STRIDE}" in run.data.tags["sray.protocol"]
    assert run.data.params["protocol.stride"] == str(STRIDE) and run.data.params["protocol.n_source"] == str(N_SOURCE)
    assert "mean/ssim" not in run.data.metrics
    scene = test_scenes[0]
    assert run.data.metrics[f"{scene}/miou"] == pytest.approx(report["scenes"][scene]["dataset_level"]["miou"])
    assert run.data.metrics["mean/miou_per_image"] == pytest.approx(mean["per_image"]["miou"])
    assert client.get_metric_history(run.info.run_id, "mean/miou")[0].step == 12
    assert "metrics.json" in [f.path for f in client.list_artifacts(run.info.run_id)]
    logged = {Path(f.path).name for f in client.list_artifacts(run.info.run_id, f"renders/{scene}")}
    view_id = report["scenes"][scene]["views"][0]["query_id"]
    assert {f"{view_id}_{k}.png" for k in ("pred", "gt", "error", "panel")} <= logged


def test_whole_image_eval_scores_ssim(tiny_checkpoint, tiny_shards, mlflow_uri, tmp_path, capsys):
    from sray.jobs.cli import main

    out = tmp_path / "eval"
    code = main(["eval", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--n-source",
                 str(N_SOURCE), "--out", str(out), "--tracking-uri", mlflow_uri, "--render", "full"])
    printed = capsys.readouterr().out
    assert code == 0
    report = json.loads((out / "metrics.json").read_text())
    assert report["protocol"] == _expected_protocol(tiny_shards, N_SOURCE, 1, "full")
    for block in [*report["scenes"].values(), report["mean"]]:
        assert isinstance(block["colour"]["ssim"], float) and -1.0 <= block["colour"]["ssim"] <= 1.0
    manifest = read_manifest(tiny_shards)
    for scene, block in report["scenes"].items():  # whole renders: the full image size
        gt = cv2.imread(str(out / block["views"][0]["pngs"]["gt"]))
        assert list(gt.shape[:2]) == manifest.scenes[scene].image_size
    header = next(line for line in printed.splitlines() if line.startswith("scene "))
    assert header.rstrip().endswith("SSIM") and "pixels: whole images (stride 1)" in printed


def test_eval_refuses_bad_input(tiny_checkpoint, tiny_shards, mlflow_uri, tmp_path, capsys):
    from sray.jobs.cli import main

    args = ["eval", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--out", str(tmp_path),
            "--tracking-uri", mlflow_uri]
    assert main([*args, "--scenes", "no_such_scene"]) == 2
    assert "scenes ['no_such_scene'] not found" in capsys.readouterr().err
    train_scene = next(s for s, e in read_manifest(tiny_shards).scenes.items() if e.meta["role"] == "train")
    assert main([*args, "--scenes", train_scene, "--stride", "0"]) == 2
    assert "--stride is 0" in capsys.readouterr().err
    assert main([*args[:2], str(tmp_path / "nowhere"), *args[3:]]) == 2
    assert "nowhere" in capsys.readouterr().err


@pytest.mark.parametrize(("extra", "refused"), [
    (["--method", "2d-transfer", "--segmenter", "seg", "--render", "full"], "--render does not apply to --method "
                                                                           "2d-transfer (it reads --segmenter)"),
    (["--method", "2d-transfer", "--segmenter", "seg", "--fast-stride", "8", "--fast-confidence", "0.9"],
     "--fast-stride, --fast-confidence do not apply to --method 2d-transfer"),  # their default values: still given
    (["--method", "2d-transfer", "--segmenter", "seg", "--checkpoint", "ckpt"], "--checkpoint does not apply"),
    (["--checkpoint", "ckpt", "--segmenter", "seg"], "--segmenter does not apply to --method sray (it reads "
                                                     "--checkpoint, --render, --fast-stride, --fast-confidence, "
                                                     "--fast-temperature, --calibrate)"),
])
def test_eval_refuses_flags_the_method_does_not_read(extra, refused, tmp_path, capsys):
    """A flag the chosen method's record does not read is refused (exit 2, the flag and the method named) before
    anything is loaded or written, instead of being silently ignored."""
    from sray.jobs.cli import main

    out = tmp_path / "eval"
    assert main(["eval", "--data", str(tmp_path / "shards"), "--out", str(out), *extra]) == 2
    assert refused in capsys.readouterr().err and not out.exists()


def test_eval_records_the_flags_typed_whatever_their_value():
    """Only typed flags count as given (the defaults of --render and --fast-* are not refused)."""
    from sray.jobs.cli import build_parser

    parse = build_parser().parse_args
    assert parse(["eval", "--method", "2d-transfer", "--segmenter", "s", "--data", "d"]).given == ("--segmenter",)
    assert parse(["eval", "--checkpoint", "c", "--data", "d", "--render", "fast"]).given == ("--checkpoint",
                                                                                            "--render")


def test_eval_scores_each_split_and_the_same_data_has_no_gap(tiny_checkpoint, tiny_shards, mlflow_uri, tmp_path,
                                                             capsys) -> None:
    """``--split NAME=DIR`` scores the same model on another folder (here the same one: no gap) beside --data;
    ``--calibrate`` fits the fast rule's temperature on validation shards and every split is scored with it."""
    from sray.jobs.cli import main

    out = tmp_path / "eval"
    args = ["eval", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--n-source", "3",
            "--stride", "4", "--out", str(out), "--tracking-uri", mlflow_uri]
    assert main([*args, "--split", "again"]) == 2 and "NAME=DIR" in capsys.readouterr().err
    assert main([*args, "--split", f"again={tiny_shards}", "--calibrate", str(tiny_shards)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "splits.json").read_text())
    main_report = json.loads((out / "metrics.json").read_text())
    again = json.loads((out / "again" / "metrics.json").read_text())
    assert summary["splits"]["again"]["miou"] == pytest.approx(100 * again["mean"]["dataset_level"]["miou"])
    assert summary["splits"]["again"]["miou"] == pytest.approx(100 * main_report["mean"]["dataset_level"]["miou"])
    assert summary["splits"]["again"]["gap_miou"] == pytest.approx(0.0, abs=1e-9)
    assert "largest gap: 0.0 mIoU points (data -> again)" in printed
    calibration = json.loads((out / "calibration.json").read_text())
    assert calibration["rays"] > 0 and calibration["nll_fitted"] <= calibration["nll_at_1"] + 1e-9
    for report in (main_report, again):  # both splits scored with the fitted temperature
        assert f"at temperature {calibration['temperature']:.3g}" in report["protocol"]["render"]
